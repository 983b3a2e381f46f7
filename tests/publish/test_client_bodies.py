"""The bodies the client sends are byte for byte those it built by hand before issue 31.

Each ``old_*`` function is the client's code before its bodies came from the message types next to
their decoders (publish/); the client now builds them with those encoders. Every request goes
through the client's real method, captured where it would leave for Zenoh, and is compared as the
bytes it is sent as (``encode_body``, or the attachment's bytes).
"""

from __future__ import annotations

import asyncio
import json
import numbers
from collections.abc import Iterable, Mapping
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.client.cell_trajectory import CellGoalHandle, send_cell_trajectory
from urdaemon.client.command_lease import Lease, LeaseHeld
from urdaemon.client.robot_client import RobotClient
from urdaemon.client.session import encode_body
from urdaemon.errors import GoalRejected, UrDaemonError
from urdaemon.publish.keys import CellKeys, RobotKeys

TOKEN = "ab" * 16
KEYS = RobotKeys("cell", "alice")
POSE = [0.4, -0.1, 0.3, 3.1, 0.0, 0.0]
POINTS = [{"positions": [0.0, 1.0], "time_from_start": 1}, {"positions": [0.5, 1.5], "time_from_start": 2.5}]

# ---- the client's code before: each body built by hand --------------------------------------------


def _put_given(body: dict[str, Any], **fields: object) -> None:
    body.update({name: value for name, value in fields.items() if value is not None})


def _pose_list(poses: Any) -> list[Any]:
    items = list(poses)
    if items and all(isinstance(v, numbers.Real) for v in items):
        return [items]
    return [list(p) if isinstance(p, Iterable) and not isinstance(p, str) else p for p in items]


def old_trajectory(
    points: Any,
    *,
    joint_names: Any = None,
    tolerances: Any = None,
    preempt: bool = False,
    passthrough: bool = False,
) -> dict[str, Any]:
    body: dict[str, Any] = {"points": list(points), "preempt": preempt}
    if passthrough:
        body["passthrough"] = True
    if joint_names is not None:
        body["joint_names"] = list(joint_names)
    if tolerances is not None:
        body["tolerances"] = tolerances
    return body


def old_move(
    positions: Any,
    *,
    duration: Any = None,
    joint_names: Any = None,
    velocity_scale: float = 1.0,
    acceleration_scale: float = 1.0,
    preempt: bool = False,
) -> dict[str, Any]:
    body: dict[str, Any] = {
        "positions": list(positions),
        "velocity_scale": velocity_scale,
        "acceleration_scale": acceleration_scale,
        "preempt": preempt,
    }
    if duration is not None:
        body["duration"] = duration
    if joint_names is not None:
        body["joint_names"] = list(joint_names)
    return body


def old_move_pose(
    pose: Any,
    *,
    frame: str = "base",
    configuration: Any = None,
    duration: Any = None,
    velocity_scale: float = 1.0,
    acceleration_scale: float = 1.0,
    tolerances: Any = None,
    preempt: bool = False,
) -> dict[str, Any]:
    body: dict[str, Any] = {"pose": list(pose), "frame": frame}
    body.update(velocity_scale=velocity_scale, acceleration_scale=acceleration_scale, preempt=preempt)
    _put_given(body, configuration=configuration, duration=duration, tolerances=tolerances)
    return body


def old_linear(poses: Any, *, frame: str = "base", blend_radii: Any = None, **limits: Any) -> dict[str, Any]:
    body: dict[str, Any] = {"poses": _pose_list(poses), "frame": frame}
    _put_given(body, blend_radii=None if blend_radii is None else list(blend_radii), **limits)
    return body


def old_cell_goal(parts: Mapping[str, Any], on_abort: str) -> dict[str, Any]:
    robots = {
        name: dict(part) if isinstance(part, Mapping) else {"points": list(part)}
        for name, part in parts.items()
    }
    return {"robots": robots, "on_abort": on_abort}


# ---- where the client's requests leave ------------------------------------------------------------


class Sent:
    """What the client sent: (key, body bytes, attachment) of each query and put."""

    def __init__(self) -> None:
        self.items: list[tuple[str, bytes, bytes | None]] = []
        self.reply: dict[str, Any] = {}

    async def request(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = 0.0,
        attachment: bytes | None = None,
    ) -> dict[str, Any]:
        self.items.append((key, encode_body(body or {}), attachment))
        return self.reply

    def put(self, key: str, payload: bytes, *, attachment: bytes | None = None) -> None:
        self.items.append((key, payload, attachment))

    @property
    def session(self) -> Sent:
        return self

    @property
    def holder(self) -> str:
        return "tests (pid 1 on host)"

    def subscribe(self, key: str, maxsize: int = 0) -> object:
        return object()

    def unsubscribe(self, sub: object) -> None:
        pass


def robot_client(sent: Sent) -> RobotClient:
    """A robot handle whose goals and commands are captured where they would be sent."""
    robot = RobotClient(sent, KEYS, Lease(sent, KEYS))  # type: ignore[arg-type]

    async def send_goal(key: str, body: dict[str, Any]) -> None:
        await sent.request(key, body)

    async def command(key: str, body: dict[str, Any], answer: str, timeout: float) -> dict[str, Any]:
        return await sent.request(key, body)

    robot._send_goal = send_goal  # type: ignore[method-assign,assignment]
    robot._command = command  # type: ignore[method-assign]
    robot._stream_attachment = lambda: TOKEN.encode()  # type: ignore[method-assign]
    return robot


def sent_by(sent: Sent) -> bytes:
    ((_, body, _),) = sent.items
    return body


# ---- a robot's goals, cancel and freedrive ---------------------------------------------------------

TRAJECTORIES: list[tuple[Any, dict[str, Any]]] = [
    (POINTS, {}),
    (POINTS, {"preempt": True, "passthrough": True}),
    (tuple(POINTS), {"joint_names": ("a", "b"), "tolerances": {"goal": 0.01, "path": [0.1, 0.2]}}),
    ([], {"tolerances": {}, "passthrough": False}),
    ([{"positions": "garbage"}], {"joint_names": []}),
]


@pytest.mark.parametrize(("points", "options"), TRAJECTORIES)
async def test_a_trajectory_goals_body_is_unchanged(points: Any, options: dict[str, Any]) -> None:
    points = list(points)
    sent = Sent()
    await robot_client(sent).send_trajectory(points, **options)
    assert sent.items[0][0] == KEYS.goal_trajectory
    assert sent_by(sent) == encode_body(old_trajectory(points, **options))


MOVES: list[dict[str, Any]] = [
    {},
    {"duration": 3.0, "preempt": True},
    {"joint_names": ["j1", "j2"], "velocity_scale": 0.5, "acceleration_scale": 0.25, "duration": 0},
]


@pytest.mark.parametrize("options", MOVES)
async def test_a_move_goals_body_is_unchanged(options: dict[str, Any]) -> None:
    sent = Sent()
    await robot_client(sent).move((0.5, -1.2, 1), **options)
    assert sent.items[0][0] == KEYS.goal_move
    assert sent_by(sent) == encode_body(old_move((0.5, -1.2, 1), **options))


POSE_MOVES: list[dict[str, Any]] = [
    {},
    {"frame": "world", "configuration": {"elbow": "up", "shoulder": "left"}, "duration": 2.0},
    {"tolerances": {"goal_time": 1}, "preempt": True, "velocity_scale": 0.1, "configuration": {}},
]


@pytest.mark.parametrize("options", POSE_MOVES)
async def test_a_pose_goals_body_is_unchanged(options: dict[str, Any]) -> None:
    sent = Sent()
    await robot_client(sent).move_pose(POSE, **options)
    assert sent_by(sent) == encode_body(old_move_pose(POSE, **options))


LINEARS: list[tuple[Any, dict[str, Any]]] = [
    (POSE, {}),
    ([POSE, tuple(POSE)], {"blend_radii": (0.01,), "speed": 0.25, "angular_jerk": 3}),
    ([POSE, [0, 0, 0.5, 0, 0, 0], POSE], {"frame": "world", "blend_radii": [0, 0.02], "acceleration": 1.0}),
    ([POSE, 5, "xyz"], {"jerk": 2.0, "angular_speed": 0.5, "angular_acceleration": 1.5}),
    ([], {}),
]


@pytest.mark.parametrize(("poses", "options"), LINEARS)
async def test_a_linear_goals_body_is_unchanged(poses: Any, options: dict[str, Any]) -> None:
    sent = Sent()
    await robot_client(sent).move_linear(poses, **options)
    assert sent.items[0][0] == KEYS.goal_linear
    assert sent_by(sent) == encode_body(old_linear(poses, **options))


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-5, 5), min_size=1, max_size=8),
    st.none() | st.floats(0.0, 10.0),
    st.none() | st.lists(st.text(max_size=5), max_size=8),
    st.floats(0.0, 1.0),
    st.booleans(),
)
def test_any_moves_body_is_unchanged(
    positions: list[Any], duration: float | None, names: list[str] | None, scale: float, preempt: bool
) -> None:
    sent = Sent()
    options: dict[str, Any] = {
        "duration": duration,
        "joint_names": names,
        "velocity_scale": scale,
        "preempt": preempt,
    }
    asyncio.run(robot_client(sent).move(positions, **options))
    assert sent_by(sent) == encode_body(old_move(positions, **options))


@pytest.mark.parametrize("goal_id", [None, "g-1", "a goal id with spaces"])
async def test_a_cancels_body_is_unchanged(goal_id: str | None) -> None:
    sent = Sent()
    await robot_client(sent).cancel(goal_id)
    assert sent.items[0][0] == KEYS.goal_cancel
    assert sent_by(sent) == encode_body({} if goal_id is None else {"goal_id": goal_id})


@pytest.mark.parametrize("active", [True, False])
def test_a_freedrive_commands_body_is_unchanged(active: bool) -> None:
    sent = Sent()
    robot_client(sent).freedrive(active)
    assert sent.items == [(KEYS.command_freedrive, encode_body({"active": active}), TOKEN.encode())]


# ---- the lease -----------------------------------------------------------------------------------


def lease(sent: Sent) -> Lease:
    held = Lease(sent, KEYS)  # type: ignore[arg-type]

    def declare() -> None:
        held._session = "0123456789abcdef" * 2

    held._declare = declare  # type: ignore[method-assign]
    return held


@pytest.mark.parametrize(
    ("force", "reason"), [(False, ""), (True, "the cell is mine now"), (False, "ignored")]
)
async def test_an_acquires_body_is_unchanged(force: bool, reason: str) -> None:
    sent = Sent()
    sent.reply = {"ok": False, "reason": "lease: refused by the test"}
    with pytest.raises(LeaseHeld):
        await lease(sent).acquire(force=force, reason=reason)
    old: dict[str, Any] = {"action": "acquire", "session": "0123456789abcdef" * 2}
    old["holder"] = sent.holder
    if force:
        old.update(force=True, reason=reason)
    assert sent.items == [(KEYS.lease, encode_body(old), None)]


async def test_a_releases_and_a_shows_bodies_are_unchanged() -> None:
    sent = Sent()
    held = lease(sent)
    held.token = TOKEN
    sent.reply = {"ok": True}
    await held.release()
    await held.show()
    assert sent.items == [
        (KEYS.lease, encode_body({"action": "release"}), TOKEN.encode()),
        (KEYS.lease, encode_body({"action": "show"}), None),
    ]


# ---- a cell goal and its cancel -------------------------------------------------------------------


class CellSent(Sent):
    """A client of the cell whose every robot grants its lease at once."""

    async def robot(self, name: str, *, cell: str | None = None) -> Any:
        held = lease(self)
        held.token = f"{name}-token"
        return type("Robot", (), {"lease": held})()


CELL_GOALS: list[tuple[dict[str, Any], str]] = [
    ({"alice": POINTS}, "stop_all"),
    ({"alice": POINTS, "bob": {"points": POINTS, "tolerances": {"goal": 0.1}, "preempt": True}}, "continue"),
    ({"bob": {"joint_names": ["x"], "points": []}, "alice": tuple(POINTS)}, "nonsense"),
]


@pytest.mark.parametrize(("parts", "on_abort"), CELL_GOALS)
async def test_a_cell_goals_body_and_tokens_are_unchanged(parts: dict[str, Any], on_abort: str) -> None:
    parts = {name: part if isinstance(part, Mapping) else list(part) for name, part in parts.items()}
    sent = CellSent()
    sent.reply = {"accepted": False, "reason": "refused by the test"}
    with pytest.raises(GoalRejected):
        await send_cell_trajectory(sent, "cell", parts, on_abort=on_abort)  # type: ignore[arg-type]
    tokens = {name: f"{name}-token" for name in parts}
    key, body, attachment = sent.items[-1]
    assert key == CellKeys("cell").goal_trajectory
    assert body == encode_body(old_cell_goal(parts, on_abort))
    assert attachment == json.dumps(tokens).encode()


async def test_a_cell_goals_cancel_is_unchanged() -> None:
    sent = CellSent()
    tokens = json.dumps({"alice": TOKEN}).encode()
    reply = {"goal_id": "cg-1", "result_key": "0" * 64}
    handle = CellGoalHandle(sent, CellKeys("cell"), reply, tokens, object())  # type: ignore[arg-type]
    await handle.cancel()
    assert sent.items == [(CellKeys("cell").goal_cancel, encode_body({"goal_id": "cg-1"}), tokens)]


async def test_the_cancel_of_an_unfollowable_cell_goal_is_unchanged() -> None:
    sent = CellSent()
    sent.reply = {"accepted": True, "goal_id": 7, "result_key": "not a key"}
    with pytest.raises(UrDaemonError, match="result_key"):
        await send_cell_trajectory(sent, "cell", {"alice": POINTS})  # type: ignore[arg-type]
    key, body, attachment = sent.items[-1]
    assert (key, body) == (CellKeys("cell").goal_cancel, encode_body({"goal_id": "7"}))
    assert attachment == json.dumps({"alice": "alice-token"}).encode()
