"""Headless Chromium for the browser tests: finding it (or skipping, or failing under CI), and
opening one page in a fresh browser with its own profile.

The browser is Debian's ``chromium`` package, driven by Playwright (PyPI ``playwright``, its own
driver; no browser download). WebGL renders in software there (SwiftShader through ANGLE).
Without either, the tests skip and say which is missing, unless ``URDAEMON_REQUIRE_BROWSER=1``
(set by .ci/run), where a missing browser is a failure.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import os
import re
import shutil
import sys
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from playwright.async_api import Page

__all__ = ["FLAGS", "HEIGHT", "PICTURE_SIZE", "REQUIRE_ENV", "WIDTH", "chromium_or_skip", "chromium_page"]

REQUIRE_ENV = "URDAEMON_REQUIRE_BROWSER"
"""Set to 1: a missing browser fails the browser tests instead of skipping them."""
FLAGS = (
    "--headless=new",
    "--no-sandbox",  # CI runs as root
    "--use-gl=angle",
    "--use-angle=swiftshader",  # WebGL in software: no GPU on these machines
    "--enable-unsafe-swiftshader",
    # the plots' 2D canvases drawn by the renderer, as Chrome does when it falls back to software
    # WebGL. Drawn through SwiftShader instead, each canvas frame made the renderer's main thread
    # wait until the GPU process had finished everything queued before it ("GPU backpressure" in
    # Chrome's trace); on a busy machine that wait took 5-20 s, several in a row, and a click
    # waited behind it for over two minutes.
    "--disable-accelerated-2d-canvas",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
    # what Playwright's own launch adds: no throttling of a page nobody looks at, colours as drawn
    "--disable-background-timer-throttling",
    "--disable-backgrounding-occluded-windows",
    "--disable-renderer-backgrounding",
    "--disable-ipc-flooding-protection",
    "--disable-hang-monitor",
    "--disable-dev-shm-usage",
    "--disable-extensions",
    "--disable-breakpad",
    "--force-color-profile=srgb",
    "--hide-scrollbars",
    "--mute-audio",
)
WIDTH, HEIGHT = 960, 540
"""The page's size in CSS pixels (one device pixel each): the screenshot's size. Every frame is
drawn in software, so the tests' page is about half the pixels of the picture's (``PICTURE_SIZE``)."""
PICTURE_SIZE = 1280, 720
"""The page's size for the picture in docs/ (``URDAEMON_VIEW_PNG``)."""
PAGE_TIMEOUT_MS = 120_000
"""Playwright's bound on any one page action (load, click, key, screenshot) on a busy machine."""
CLOSE_TIMEOUT_S = 30.0
"""Chromium must end within this long of SIGTERM, else it is killed."""
STARTUP_LINES = 200
"""At most this many lines of Chromium's standard error before its DevTools address."""


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
async def chromium_page(
    executable: str, url: str, size: tuple[int, int] = (WIDTH, HEIGHT)
) -> AsyncIterator[Page]:
    """``url`` open in a new headless Chromium (a fresh profile, removed at the end) in a page of
    ``size`` (CSS pixels) until the block ends."""
    from playwright.async_api import async_playwright

    with tempfile.TemporaryDirectory(prefix="urdaemon-chromium-") as folder:
        async with _chromium(executable, Path(folder)) as devtools, async_playwright() as playwright:
            browser = await playwright.chromium.connect_over_cdp(devtools, timeout=PAGE_TIMEOUT_MS)
            try:
                page = await browser.new_page(
                    viewport={"width": size[0], "height": size[1]}, device_scale_factor=1
                )
                page.set_default_timeout(PAGE_TIMEOUT_MS)
                # what the page says, in the test's captured output (shown when it fails)
                page.on("console", lambda message: print(f"page console {message.type}: {message.text}"))
                page.on("pageerror", lambda error: print(f"page error: {error}"))
                page.on("crash", lambda _: print("page crashed"))
                await page.goto(url)
                yield page
            finally:
                await browser.close()


@contextlib.asynccontextmanager
async def _chromium(executable: str, profile: Path) -> AsyncIterator[str]:
    """Chromium running in this process's session at a plain priority (tests/browser/plain_priority.py
    says why), with its DevTools on a port the OS picks; yields the DevTools address."""
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        str(Path(__file__).with_name("plain_priority.py")),
        executable,
        *FLAGS,
        f"--user-data-dir={profile}",
        "--remote-debugging-address=127.0.0.1",
        "--remote-debugging-port=0",
        "about:blank",
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    assert process.stderr is not None
    draining: asyncio.Task[None] | None = None
    try:
        devtools = await asyncio.wait_for(_devtools_address(process.stderr), PAGE_TIMEOUT_MS / 1000)
        draining = asyncio.create_task(_drain(process.stderr))  # a full pipe would block chromium
        yield devtools
    finally:
        if process.returncode is None:
            process.terminate()
            try:
                await asyncio.wait_for(process.wait(), CLOSE_TIMEOUT_S)
            except TimeoutError:
                process.kill()
                await process.wait()
        if draining is not None:
            draining.cancel()


async def _devtools_address(stderr: asyncio.StreamReader) -> str:
    """The ``ws://`` address Chromium prints once its DevTools listen (at most ``STARTUP_LINES``
    lines of its standard error)."""
    seen = []
    for _ in range(STARTUP_LINES):
        line = (await stderr.readline()).decode(errors="replace")
        if not line:
            break
        found = re.search(r"DevTools listening on (ws://\S+)", line)
        if found:
            return found.group(1)
        seen.append(line.rstrip())
    raise AssertionError("chromium printed no DevTools address:\n" + "\n".join(seen[-20:]))


async def _drain(stderr: asyncio.StreamReader) -> None:
    while await stderr.read(65536):
        pass
