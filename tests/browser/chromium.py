"""Headless Chromium for the browser tests: finding it (or skipping, or failing under CI), and
opening one page in a fresh browser with its own profile.

The browser is Debian's ``chromium`` package, driven by Playwright (PyPI ``playwright``, its own
driver; no browser download). WebGL renders in software there (SwiftShader through ANGLE).
Without either, the tests skip and say which is missing, unless ``URDAEMON_REQUIRE_BROWSER=1``
(set by .ci/run), where a missing browser is a failure.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import shutil
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from playwright.async_api import Page

__all__ = ["FLAGS", "HEIGHT", "REQUIRE_ENV", "WIDTH", "chromium_or_skip", "chromium_page"]

REQUIRE_ENV = "URDAEMON_REQUIRE_BROWSER"
"""Set to 1: a missing browser fails the browser tests instead of skipping them."""
FLAGS = (
    "--headless=new",
    "--no-sandbox",  # CI runs as root
    "--use-gl=angle",
    "--use-angle=swiftshader",  # WebGL in software: no GPU on these machines
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
)
WIDTH, HEIGHT = 1280, 720
"""The page's size in CSS pixels (one device pixel each): the screenshot's size."""
PAGE_TIMEOUT_MS = 120_000
"""Playwright's bound on any one page action (load, click, key, screenshot) on a busy machine."""


def chromium_or_skip() -> str:
    """The path of the chromium executable; skip (or fail under ``URDAEMON_REQUIRE_BROWSER=1``),
    naming what is missing, when chromium or Playwright is not installed."""
    missing = []
    path = shutil.which("chromium")
    if path is None:
        missing.append("chromium (Debian package: apt-get install chromium)")
    if importlib.util.find_spec("playwright") is None:
        missing.append("playwright (PyPI: pip install playwright)")
    if missing:
        reason = "the browser tests need " + " and ".join(missing)
        if os.environ.get(REQUIRE_ENV) == "1":
            pytest.fail(f"{reason} ({REQUIRE_ENV}=1)", pytrace=False)
        pytest.skip(reason)
    assert path is not None
    return path


@contextlib.asynccontextmanager
async def chromium_page(executable: str, url: str) -> AsyncIterator[Page]:
    """``url`` open in a new headless Chromium (a fresh profile, removed at the end) until the
    block ends."""
    from playwright.async_api import async_playwright

    with tempfile.TemporaryDirectory(prefix="urdaemon-chromium-") as folder:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(
                executable_path=_niced(executable, Path(folder)),
                args=list(FLAGS),
                headless=True,
                timeout=PAGE_TIMEOUT_MS,
            )
            try:
                page = await browser.new_page(
                    viewport={"width": WIDTH, "height": HEIGHT}, device_scale_factor=1
                )
                page.set_default_timeout(PAGE_TIMEOUT_MS)
                await page.goto(url)
                yield page
            finally:
                await browser.close()


def _niced(executable: str, folder: Path) -> str:
    """A launcher that runs ``executable`` at the lowest CPU priority (``nice -n 19``; its renderer
    and GPU processes inherit it). Software WebGL takes one and a half of this machine's two cores
    for as long as a page is open: at normal priority it starved the real-time tests (fake
    controllers, the daemon's cycles) of a suite run beside this one."""
    launcher = folder / "chromium"
    launcher.write_text(f'#!/bin/sh\nexec nice -n 19 "{executable}" "$@"\n', encoding="utf-8")
    launcher.chmod(0o755)
    return str(launcher)
