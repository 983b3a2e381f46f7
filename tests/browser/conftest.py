"""Fixtures: the demo cell and ``urdaemon view`` in the test's loop (as in tests/view/), and the
view's page open in a headless Chromium, connected to the view's viser server."""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import pytest

from tests.browser.chromium import HEIGHT, PICTURE_SIZE, WIDTH, chromium_or_skip, chromium_page
from tests.browser.picture import connected_client
from tests.integration.conftest import running_daemon
from tests.view.conftest import DEMO_CELL, Viewed
from urdaemon.view.app import running_view

if TYPE_CHECKING:
    from playwright.async_api import Page

PICTURE_ENV = "URDAEMON_VIEW_PNG"
"""Names a path: the cell's screenshot is saved there (the page then has ``PICTURE_SIZE``)."""
CONNECT_TIMEOUT_S = 90.0
"""The page must load viser's client and send its first camera message within this long (a busy
machine, WebGL in software)."""


@dataclass
class Opened:
    """The cell and its view (``viewed``), and the view's ``page`` in Chromium with its viser
    ``page_client`` (a ``ClientHandle``: its camera)."""

    viewed: Viewed
    page: Page
    page_client: Any


@pytest.fixture
async def opened() -> AsyncIterator[Opened]:
    chromium = chromium_or_skip()
    size = PICTURE_SIZE if os.environ.get(PICTURE_ENV) else (WIDTH, HEIGHT)
    async with (
        running_daemon(DEMO_CELL) as (daemon, client),
        running_view(client, port=0) as view,
        chromium_page(chromium, view.url, size) as page,
    ):
        page_client = await connected_client(view.server, CONNECT_TIMEOUT_S)
        yield Opened(Viewed(daemon, client, view), page, page_client)
