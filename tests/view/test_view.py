"""``urdaemon view`` against the demo cell over real Zenoh, with a real viser server on a port the OS
chose; no browser: the page's widgets are set from Python as the page would set them, which runs the
same callbacks.

Reproduction on the code before issue 18: there was no ``urdaemon.view`` (and no ``view`` command), so
every test here fails at import.
"""

from __future__ import annotations

import asyncio
import math
import urllib.request
from typing import Any

import pytest

from tests.view.conftest import Viewed, close, tf_links
from urdaemon.client import Client, Subscription
from urdaemon.description.kinematics import compose_poses
from urdaemon.view.scene import PROBLEM_COLOR

pytestmark = pytest.mark.timeout(120)

SHOWN = 1e-4
"""How close a drawn pose is to the daemon's (m, and quaternion components): viser does not send a
pose within ``numpy.allclose`` (relative 1e-5) of the one it shows, so the last few micrometres of a
motion may stay unsent."""
SAMPLES = 3000
"""At most this many joint_states (6 s of alice at 500 Hz) for anything a test waits on."""


def _scene_pose(viewed: Viewed, link: str) -> tuple[float, ...]:
    """The link's pose as the scene has it, as tf gives poses: x, y, z, qx, qy, qz, qw."""
    frame = viewed.view.scene.frames[link]
    w, x, y, z = (float(v) for v in frame.wxyz)
    return (*(float(v) for v in frame.position), x, y, z, w)


def _same_pose(a: tuple[float, ...], b: tuple[float, ...], tol: float) -> bool:
    """Whether two poses are within ``tol`` (a quaternion and its negative are the same rotation)."""
    return close(a[:3], b[:3], tol) and (
        close(a[3:], b[3:], tol) or close(a[3:], tuple(-v for v in b[3:]), tol)
    )


def _drawn_tcp(viewed: Viewed, robot: str) -> tuple[float, ...]:
    """The robot's TCP frame in the world as the scene draws it: its parent link's node (named in its
    path, ``/cell/<link>/tcp``) composed with its own pose."""
    handle = viewed.view.scene.tcp_frames[robot]
    link = handle.name.split("/")[2]
    w, x, y, z = (float(v) for v in handle.wxyz)
    return compose_poses(_scene_pose(viewed, link), (*(float(v) for v in handle.position), x, y, z, w))


async def _tcp_pose_in_world(viewed: Viewed, robot: str) -> tuple[float, ...]:
    """The robot's next ``tcp_pose`` (in its base frame) put in the world with the base as drawn."""
    poses = viewed.client.subscribe(f"demo_cell/{robot}/tcp_pose", maxsize=5)
    try:
        message = await poses.get_json(10.0)
    finally:
        viewed.client.unsubscribe(poses)
    pose = (*message["position"], *message["orientation"])
    return compose_poses(_scene_pose(viewed, message["frame"]), tuple(float(v) for v in pose))


async def _next_states(states: Subscription, check: Any, what: str) -> dict[str, Any]:
    """The first joint_states message (at most ``SAMPLES``) for which ``check`` holds."""
    for _ in range(SAMPLES):
        message = await states.get_json(10.0)
        if check(message):
            return message
    raise AssertionError(f"{what}: not within {SAMPLES} joint_states")


async def _submitted(viewed: Viewed, robot: str) -> None:
    """Wait for what the page's last action handed to the loop."""
    await asyncio.wait_for(asyncio.wrap_future(viewed.view.panels[robot].pending[-1]), 30.0)


async def test_the_view_serves_its_page(viewed: Viewed) -> None:
    view = viewed.view
    assert view.url.startswith("http://127.0.0.1:")
    assert view.url.endswith(f":{view.server.get_port()}")
    body = await asyncio.to_thread(lambda: urllib.request.urlopen(view.url, timeout=10).read())
    assert b"<html" in body.lower()
    assert b"viser" in body.lower()
    assert set(view.panels) == {"alice", "bob"}
    assert list(view.panels["alice"].sliders) == [
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ]


async def test_every_link_is_drawn_where_the_daemons_tf_puts_it(viewed: Viewed) -> None:
    view = viewed.view
    await viewed.until("both robots drawn", lambda: view.moves >= 1)
    tf = await tf_links(viewed.client)
    assert set(tf) <= set(view.scene.frames)
    for link, pose in tf.items():
        assert close(_scene_pose(viewed, link), tuple(pose), SHOWN), link
    assert _scene_pose(viewed, "alice_base")[:3] == pytest.approx((0.5, 0.0, 0.0), abs=1e-9)
    assert _scene_pose(viewed, "bob_base")[:3] == pytest.approx((-0.5, 0.0, 0.0), abs=1e-9)
    # the URDF's visuals are drawn on both robots, and each has its TCP frame
    assert view.scene.meshes.get("alice")
    assert view.scene.meshes.get("bob")
    await viewed.until("TCP frames", lambda: set(view.scene.tcp_frames) == {"alice", "bob"})
    for robot in ("alice", "bob"):  # where the daemon's own tcp_pose puts the TCP
        assert _same_pose(_drawn_tcp(viewed, robot), await _tcp_pose_in_world(viewed, robot), SHOWN), robot
    # a set_tcp moves the drawn TCP with it: 0.1 m along tool0's z and turned about its x
    alice = await viewed.client.robot("alice")
    await alice.set_tcp([0.0, 0.0, 0.1, 0.3, 0.0, 0.0])
    await alice.release()
    expected = await _tcp_pose_in_world(viewed, "alice")
    await viewed.until("the new TCP drawn", lambda: _same_pose(_drawn_tcp(viewed, "alice"), expected, SHOWN))
    assert not _same_pose(_scene_pose(viewed, "alice_tool0"), expected, 0.05)  # the TCP is off tool0 now


async def test_the_scene_follows_a_moving_robot(viewed: Viewed) -> None:
    view = viewed.view
    await viewed.until("first draw", lambda: view.moves >= 1)
    before = _scene_pose(viewed, "bob_tool0")
    bob = await viewed.client.robot("bob")
    goal = await bob.move([0.6, -1.2, 1.3, -1.5, -1.5, 0.4], duration=1.0)
    assert (await goal.result(timeout=30.0))["status"] == "succeeded"
    await bob.release()
    for _ in range(100):  # the goal ends within tolerance: the robot may still settle for a moment
        tf = await tf_links(viewed.client)
        await view.drawn(10.0)
        if close(_scene_pose(viewed, "bob_tool0"), tuple(tf["bob_tool0"]), SHOWN):
            break
    else:
        raise AssertionError(f"bob drawn at {_scene_pose(viewed, 'bob_tool0')}, tf has {tf['bob_tool0']}")
    assert not close(tuple(tf["bob_tool0"]), before, 1e-3)  # it did move


async def test_enabling_takes_the_lease_and_moves_nothing(viewed: Viewed) -> None:
    view = viewed.view
    panel, control = view.panels["alice"], view.controls["alice"]
    states = viewed.client.subscribe("demo_cell/alice/joint_states", maxsize=5000)
    start = tuple((await states.get_json(10.0))["position"])
    assert all(slider.disabled for slider in panel.sliders.values())
    panel.enable.value = True  # as the page's switch would
    await _submitted(viewed, "alice")
    assert control.enabled
    alice = await viewed.client.robot("alice")
    lease = await alice.lease_info()
    assert lease is not None
    assert lease["fingerprint"] == alice.lease.fingerprint
    assert close(tuple(float(s.value) for s in panel.sliders.values()), start, 1e-12)
    assert not any(slider.disabled for slider in panel.sliders.values())
    sent = control.sent
    for _ in range(200):  # 0.4 s of alice's joint_states while the stream goes out: nothing moves
        assert close(tuple((await states.get_json(10.0))["position"]), start, 1e-9)
    assert control.sent > sent + 5  # the stream was running all along
    await viewed.until("the lease event shown", lambda: "lease: acquired" in panel.events.content)


async def test_the_plots_show_the_joints_over_time(viewed: Viewed) -> None:
    view = viewed.view
    plots = view.panels["bob"].plots

    def plotted() -> int:
        return len(plots.positions.data[0])

    await viewed.until("a few samples plotted", lambda: plotted() >= 5)
    times, *lines = plots.positions.data
    assert len(lines) == 6
    assert times[-1] == 0.0  # the newest sample is "now"
    assert all(t < 0 for t in times[:-1])
    assert times[0] >= -10.0
    assert [line[-1] for line in lines] == pytest.approx([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    assert len(plots.velocities.data) == 7


async def test_a_slider_moves_its_joint_and_disabling_brakes(viewed: Viewed) -> None:
    view = viewed.view
    panel, control = view.panels["alice"], view.controls["alice"]
    panel.enable.value = True
    await _submitted(viewed, "alice")
    states = viewed.client.subscribe("demo_cell/alice/joint_states", maxsize=5000)
    start = (await states.get_json(10.0))["position"]
    target = start[0] + 0.2
    panel.sliders["shoulder_pan_joint"].value = target  # as the page's slider would
    reached = await _next_states(states, lambda m: abs(m["position"][0] - target) < 1e-4, "pan at target")
    assert close(tuple(reached["position"][1:]), tuple(start[1:]), 1e-6)  # the others stayed
    far = target + 1.5
    panel.sliders["shoulder_pan_joint"].value = far
    await _next_states(states, lambda m: m["velocity"][0] > 0.1, "pan moving")
    panel.enable.value = False
    await _submitted(viewed, "alice")
    assert not control.enabled
    assert await (await viewed.client.robot("alice")).lease_info() is None
    still = 0
    message: dict[str, Any] = {}
    for _ in range(SAMPLES):  # the robot brakes: 50 samples in a row at rest
        message = await states.get_json(10.0)
        still = still + 1 if abs(message["velocity"][0]) < 1e-6 else 0
        if still >= 50:
            break
    assert still >= 50
    assert message["position"][0] < far - 0.5  # stopped well short of the slider's target
    assert all(slider.disabled for slider in panel.sliders.values())


async def test_enable_is_refused_while_someone_else_holds_the_lease(viewed: Viewed) -> None:
    view = viewed.view
    panel, control = view.panels["bob"], view.controls["bob"]
    other = await Client.connect(viewed.client.endpoint, holder="another operator")
    try:
        await (await other.robot("bob")).ensure_lease()
        panel.enable.value = True
        await _submitted(viewed, "bob")
        assert not control.enabled
        assert "another operator" in control.refusal
        assert control.sent == 0
        assert panel.enable.value is False
        assert all(slider.disabled for slider in panel.sliders.values())
        await viewed.until("refusal shown", lambda: "another operator" in panel.status.content)
    finally:
        await other.close()


async def test_a_jog_click_moves_the_tcp_along_its_axis_and_stops(viewed: Viewed) -> None:
    view = viewed.view
    panel, control = view.panels["alice"], view.controls["alice"]
    panel.enable.value = True
    await _submitted(viewed, "alice")
    poses = viewed.client.subscribe("demo_cell/alice/tcp_pose", maxsize=5)
    before = (await poses.get_json(10.0))["position"]
    viewed.client.unsubscribe(poses)
    panel.jog_translate.value = "+z"  # a click on the page's "+z" button
    await _submitted(viewed, "alice")
    poses = viewed.client.subscribe("demo_cell/alice/tcp_pose", maxsize=5)
    after = (await poses.get_json(10.0))["position"]
    dx, dy, dz = (a - b for a, b in zip(after, before, strict=True))
    # up, and only up: how far depends on how many of the 0.3 s of twists the daemon's cycles ran
    # (fewer on a loaded machine), so the distance is only bounded below
    assert dz > 1e-3
    assert abs(dx) < 0.1 * dz
    assert abs(dy) < 0.1 * dz
    sample = view.feeds["alice"].joints()
    assert sample is not None
    assert all(abs(v) < 1e-3 for v in sample.velocities)
    assert control.enabled
    assert control.targets is not None
    assert close(tuple(control.targets), sample.positions, 1e-3)  # the stream took over from there


async def test_a_robot_that_goes_silent_is_shown_disconnected(viewed: Viewed) -> None:
    view = viewed.view
    await viewed.until("first draw", lambda: view.moves >= 1)
    label = view.scene.labels["bob"]
    assert not label.visible
    view.feeds["bob"].close()  # bob's joint_states stop reaching the view
    await viewed.until("bob disconnected", lambda: view.scene.problems["bob"] == "disconnected")
    assert label.visible
    assert "disconnected" in label.text
    assert all(tuple(handle.color) == PROBLEM_COLOR for handle, _ in view.scene.meshes["bob"])
    assert view.scene.problems["alice"] is None
    status = view.panels["bob"].status  # its text is sent at most every TEXT_S
    await viewed.until("bob's status says disconnected", lambda: "disconnected" in status.content)
    assert math.isfinite(_scene_pose(viewed, "bob_tool0")[0])


async def test_closing_the_last_page_disables_and_releases_the_lease(viewed: Viewed) -> None:
    """A page is a websocket client of the viser server: when the last one goes, no robot may keep
    streaming (its lease is released and the daemon stops it)."""
    import msgspec
    import viser
    from viser import _messages
    from websockets.asyncio.client import connect

    view = viewed.view
    ws_url = view.url.replace("http://", "ws://")
    # viser counts a page as a client once it reported its camera, as a browser does on load
    camera = _messages.ViewerCameraMessage(
        (1.0, 0.0, 0.0, 0.0), (3.0, 3.0, 3.0), 1.0, 0.01, 100.0, 480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    )
    async with connect(ws_url, subprotocols=[f"viser-v{viser.__version__}"]) as page:  # type: ignore[list-item]
        await page.send(msgspec.msgpack.encode(camera.as_serializable_dict()))
        await viewed.until("the page connected", lambda: len(view.server.get_clients()) == 1)
        view.panels["alice"].enable.value = True
        await _submitted(viewed, "alice")
        assert view.controls["alice"].enabled
        await page.close()
    await viewed.until("alice disabled", lambda: not view.controls["alice"].enabled)
    alice = await viewed.client.robot("alice")
    for _ in range(100):  # the release is on its way: ask until the daemon shows it (bounded)
        if await alice.lease_info() is None:
            break
        await view.drawn(10.0)
    assert await alice.lease_info() is None
    assert view.controls["alice"].refusal == "the last page was closed"


async def test_a_lease_taken_over_while_enabled_disables_with_the_reason(viewed: Viewed) -> None:
    view = viewed.view
    panel, control = view.panels["alice"], view.controls["alice"]
    panel.enable.value = True
    await _submitted(viewed, "alice")
    assert control.enabled
    other = await Client.connect(viewed.client.endpoint, holder="the cell supervisor")
    try:
        await (await other.robot("alice")).take_over("maintenance")
        await viewed.until("alice disabled", lambda: not control.enabled)
        await viewed.until("the reason shown", lambda: "refused" in panel.status.content)
        # the client hears of the take-over, or the daemon refuses a sample first: either names the holder
        assert "the cell supervisor" in control.refusal
        assert panel.enable.value is False
        sent = control.sent
        await view.drawn(10.0)
        await view.drawn(10.0)
        assert control.sent == sent  # nothing more is streamed
    finally:
        await other.close()
