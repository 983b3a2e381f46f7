"""``urdaemon view``'s page in a real headless Chromium (WebGL in software): the demo cell's two
robots are drawn where they stand, and a joint slider moved in the page moves its robot.

``URDAEMON_VIEW_PNG=docs/view.png python -m pytest tests/browser -n 0 -k drawn`` also saves the
screenshot of the cell (the picture in docs/view.md and the README) to that path.

Reproduction on the code before issue 18: there was no ``urdaemon.view``, so the fixtures fail at
import; with a view that drew no geometry, or put a robot elsewhere, the pixels where the daemon's
``tf`` puts each robot are background and ``test_both_robots_are_drawn_where_they_stand`` fails;
with a slider whose page changes never reach the robot's control, alice's joint_states never reach
the slider's value and ``test_a_slider_moved_in_the_page_moves_its_joint`` fails.
"""

from __future__ import annotations

import asyncio
import math
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from tests.browser.chromium import PAGE_TIMEOUT_MS
from tests.browser.conftest import PICTURE_ENV, Opened
from tests.browser.picture import Camera, Picture, SeenCamera, set_camera
from tests.view.conftest import close, tf_links
from urdaemon.client import Client, Subscription
from urdaemon.view.panel import SLIDER_STEP

if TYPE_CHECKING:
    from playwright.async_api import Locator, Page

pytestmark = pytest.mark.timeout(300)

CELL_CAMERA = Camera(position=(1.3, -2.7, 1.6), look_at=(0.62, 0.0, 0.38), fov=math.radians(38.0))
"""In front of the cell, a little to alice's side and above; the cell is left of the page's centre,
clear of the control panel on the right."""
EMPTY: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.75), (0.85, 0.0, 0.4), (-0.5, 0.0, 0.85))
"""Where nothing stands: above the world frame between the robots, under alice's forearm (between
her upper arm and her wrist), above bob (below where a problem's label would float)."""
SHOTS = 40
"""At most this many screenshots while waiting for the page to draw both robots..."""
DRAW_WAIT_S = 60.0
"""...and for at most this long (each screenshot waits for the page's next frame)."""
SAMPLES = 5000
"""At most this many joint_states (10 s of alice at 500 Hz) for anything a test waits on."""
KEY_PRESSES = 100
"""Arrow key presses on the slider's thumb: 0.1 rad at the sliders' step."""


def _standing(links: dict[str, list[float]], robot: str) -> list[tuple[float, float, float]]:
    """Points inside the robot's drawn shapes: the middle of its base (between the base link and the
    shoulder) and the shoulder joint."""
    base, shoulder = links[f"{robot}_base_link"][:3], links[f"{robot}_shoulder_link"][:3]
    middle = tuple((a + b) / 2 for a, b in zip(base, shoulder, strict=True))
    return [(middle[0], middle[1], middle[2]), (shoulder[0], shoulder[1], shoulder[2])]


async def _close_notices(page: Page) -> None:
    """Close viser's notices (e.g. "Software WebGL rendering detected"), as a user would."""
    notices = page.locator(".mantine-Notification-root")
    for _ in range(5):
        if await notices.count() == 0:
            return
        # forced: a notice is still sliding in on a busy machine (not "stable"), and its close button
        # is where it is going to be
        await notices.first.locator("button").click(force=True)
        await notices.first.wait_for(state="detached")


def _folder(page: Page, robot: str) -> Locator:
    """The robot's folder of controls in the page's panel."""
    return page.locator("div.mantine-Paper-root[data-with-border='true']").filter(
        has=page.locator("xpath=./div[1]").filter(has_text=re.compile(f"^{re.escape(robot)}$"))
    )


async def _picture(page: Page, seen: SeenCamera, robots: dict[str, list[Any]]) -> Picture:
    """A screenshot once every robot's points are drawn (at most ``SHOTS`` screenshots in
    ``DRAW_WAIT_S``); else the last one."""
    deadline = asyncio.get_running_loop().time() + DRAW_WAIT_S
    for _ in range(SHOTS):
        picture = Picture(await page.screenshot())
        if all(picture.drawn(seen.pixel(p)) > 0.5 for points in robots.values() for p in points):
            break
        if asyncio.get_running_loop().time() > deadline:
            break
    return picture


async def test_both_robots_are_drawn_where_they_stand(opened: Opened) -> None:
    page, client = opened.page, opened.viewed.client
    seen = await set_camera(opened.page_client, CELL_CAMERA)
    await _close_notices(page)
    links = await tf_links(client)
    robots = {robot: _standing(links, robot) for robot in ("alice", "bob")}
    panel = await _folder(page, "alice").bounding_box()
    assert panel is not None
    for point in [*EMPTY, *(p for points in robots.values() for p in points)]:
        assert seen.pixel(point)[0] < panel["x"] - 10, f"{point} is under the control panel"
    picture = await _picture(page, seen, robots)
    if os.environ.get(PICTURE_ENV):
        await asyncio.to_thread(Path(os.environ[PICTURE_ENV]).write_bytes, await page.screenshot())
    for robot, points in robots.items():
        for point in points:
            share = picture.drawn(seen.pixel(point))
            assert share > 0.5, f"{robot} is not drawn at {point} (pixel {seen.pixel(point)}: {share:.0%})"
    for point in EMPTY:
        assert picture.drawn(seen.pixel(point)) == 0.0, f"something is drawn at {point}, where nothing stands"


async def _slider_thumb(page: Page, robot: str, joint: str) -> Locator:
    """The thumb of the robot's slider labelled ``joint``."""
    label = _folder(page, robot).locator("label", has_text=re.compile(f"^{re.escape(joint)}$"))
    slider = await label.get_attribute("for")
    assert slider, f"{robot}'s {joint} label names no slider"
    return page.locator(f"[id='{slider}']").get_by_role("slider")


async def _next_states(states: Subscription, check: Any, what: str) -> dict[str, Any]:
    """The first joint_states message (at most ``SAMPLES``) for which ``check`` holds."""
    for _ in range(SAMPLES):
        message: dict[str, Any] = await states.get_json(10.0)
        if check(message):
            return message
    raise AssertionError(f"{what}: not within {SAMPLES} joint_states")


async def _joints(client: Client, robot: str) -> list[float]:
    """The robot's joint positions in its next joint_states message (a fresh subscription)."""
    states = client.subscribe(f"demo_cell/{robot}/joint_states", maxsize=1)
    try:
        position: list[float] = (await states.get_json(10.0))["position"]
        return position
    finally:
        client.unsubscribe(states)


async def test_a_slider_moved_in_the_page_moves_its_joint(opened: Opened) -> None:
    from playwright.async_api import expect

    page, viewed = opened.page, opened.viewed
    control, slider = viewed.view.controls["alice"], viewed.view.panels["alice"].sliders["shoulder_pan_joint"]
    client = viewed.client
    alice_start, bob_start = await _joints(client, "alice"), await _joints(client, "bob")
    enable = _folder(page, "alice").get_by_label("enable", exact=True)
    await enable.click()
    await viewed.until("alice enabled", lambda: control.enabled)
    assert await (await client.robot("alice")).lease_info() is not None, "enabling took no lease"
    thumb = await _slider_thumb(page, "alice", "shoulder_pan_joint")
    await expect(thumb).to_have_attribute("aria-disabled", "false", timeout=PAGE_TIMEOUT_MS)
    start = float(await thumb.get_attribute("aria-valuenow") or "nan")
    assert math.isclose(start, alice_start[0], abs_tol=1e-3), "enabling set the slider to the robot's joint"
    for _ in range(KEY_PRESSES):
        await thumb.press("ArrowRight")
    target = float(await thumb.get_attribute("aria-valuenow") or "nan")
    assert math.isclose(target, start + KEY_PRESSES * SLIDER_STEP, abs_tol=1e-6), (start, target)
    await viewed.until("the page's slider value at the view", lambda: math.isclose(slider.value, target))
    states = client.subscribe("demo_cell/alice/joint_states", maxsize=SAMPLES)
    try:
        reached = await _next_states(
            states, lambda m: abs(m["position"][0] - target) < 1e-3, "alice's pan at the slider's value"
        )
    finally:
        client.unsubscribe(states)
    assert close(tuple(reached["position"][1:]), tuple(alice_start[1:]), 1e-6), "alice's other joints moved"
    bob_now = await _joints(client, "bob")
    assert close(tuple(bob_now), tuple(bob_start), 1e-9), "bob moved"
    await enable.click()
    await viewed.until("alice disabled", lambda: not control.enabled)
    assert await (await client.robot("alice")).lease_info() is None, "disabling kept the lease"
