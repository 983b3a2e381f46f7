"""``urdaemon replay FILE --config``: a motion recorded on the mock cell, replayed on a fresh mock
cell, reproduces every recorded joint position within 1e-6 rad at its recorded time (±1 cycle);
``--rate`` and ``--robot``; recordings that do not match the cell are refused, naming why.

Each daemon runs in the test's loop, the command in a thread of its own (``run_cli_in_thread``);
"time" is the daemon's cycle count, which is what a goal's trajectory time follows.
"""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from tests.replay.recorder import Recorder, aligned_errors, settle
from urdaemon.recording.mcap_file import RecordingWriter

pytestmark = pytest.mark.timeout(180)

CELL = "testcell"
HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
TOLERANCE = 1e-6


async def _replay(config: Path, recording: Path, *extra: str) -> tuple[Recorder, str, int]:
    """Replay on a fresh mock cell; what its recorder saw, the command's stderr and exit code."""
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        assert daemon.node is not None
        recorder = Recorder(daemon.node.session, CELL).start()
        run = await run_cli_in_thread(
            "replay",
            str(recording),
            "--config",
            str(config),
            "--connect",
            client.endpoint,
            *extra,
            timeout=120,
        )
        await settle(recorder, "alice", 5)
        recorder.close()
    assert run.code == 0, f"exit {run.code}: {run.stderr}{run.stdout}"
    return recorder, run.stderr, run.code


def _check(recorded: Recorder, replayed: Recorder, robot: str, rate: float) -> None:
    errors, missing = aligned_errors(recorded.states(robot), replayed.states(robot), rate)
    moving = sum(1 for s in recorded.states(robot) if any(s.velocities))
    # the subscriber may miss samples (the daemon drops rather than queues on a busy machine)
    said = f"{robot}: {len(errors)} samples compared ({moving} moving), {missing} not replayed near"
    assert len(errors) + missing >= moving, said
    assert missing <= len(errors) // 2, said
    worst = max(errors)
    assert worst <= TOLERANCE, f"{robot}: a recorded position is replayed {worst:.3g} rad off"


async def test_a_recorded_motion_is_reproduced_within_1e6_rad(recorded: tuple[Path, Path, Recorder]) -> None:
    config, recording, original = recorded
    replayed, stderr, _ = await _replay(config, recording)
    assert "cell goal 1/1 (alice, bob;" in stderr, stderr
    _check(original, replayed, "alice", 1.0)
    _check(original, replayed, "bob", 1.0)


async def test_half_rate_reproduces_each_sample_at_twice_its_time(
    recorded: tuple[Path, Path, Recorder],
) -> None:
    config, recording, original = recorded
    replayed, stderr, _ = await _replay(config, recording, "--rate", "0.5")
    assert "rate 0.5 (samples)" in stderr
    _check(original, replayed, "alice", 0.5)
    _check(original, replayed, "bob", 0.5)


async def test_robot_picks_the_robots_driven(recorded: tuple[Path, Path, Recorder]) -> None:
    config, recording, original = recorded
    replayed, stderr, _ = await _replay(config, recording, "--robot", "bob")
    assert "replaying bob " in stderr
    _check(original, replayed, "bob", 1.0)
    alice = replayed.states("alice")
    assert alice
    assert all(s.positions == HOME for s in alice), "alice moved though only bob was replayed"


def _synthetic(path: Path, robot: str, names: list[str]) -> Path:
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, cell=CELL)
    for i in range(5):
        message = {
            "robot": robot,
            "names": names,
            "position": list(HOME),
            "velocity": [0.0] * 6,
            "effort": [0.0] * 6,
            "host_time_ns": 1_700_000_000_000_000_000 + 2_000_000 * i,
        }
        writer.add(f"{CELL}/{robot}/joint_states", json.dumps(message).encode(), 1)
    writer.finish()
    path.write_bytes(buffer.getvalue())
    return path


@pytest.mark.parametrize(
    ("robot", "names", "said"),
    [
        (
            "carol",
            [f"carol_j{i}" for i in range(6)],
            "robots in the recording but not in cell 'testcell': carol (recording: carol; cell: alice, bob)",
        ),
        (
            "alice",
            [f"alice_j{i}" for i in range(6)],
            "robot 'alice': joint names differ: the recording has alice_j0, alice_j1",
        ),
    ],
)
async def test_a_recording_that_does_not_match_the_cell_is_refused_naming_why(
    tmp_path: Path, robot: str, names: list[str], said: str
) -> None:
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS)
    recording = _synthetic(tmp_path / "other.mcap", robot, names)
    async with running_daemon(TWO_MOCKS) as (_daemon, client):
        run = await run_cli_in_thread(
            "replay", str(recording), "--config", str(config), "--connect", client.endpoint, timeout=60
        )
    assert run.code == 2, run.stderr
    assert said in run.stderr
    if robot == "alice":
        assert "the cell has alice_shoulder_pan_joint, alice_shoulder_lift_joint" in run.stderr


async def test_a_daemon_serving_another_cell_is_refused(tmp_path: Path) -> None:
    other = tmp_path / "other.yaml"
    other.write_text(TWO_MOCKS.replace("cell: testcell", "cell: othercell"))
    recording = _synthetic(tmp_path / "x.mcap", "alice", [f"alice_j{i}" for i in range(6)])
    async with running_daemon(TWO_MOCKS) as (_daemon, client):
        run = await run_cli_in_thread(
            "replay", str(recording), "--config", str(other), "--connect", client.endpoint, timeout=60
        )
    assert run.code == 2, run.stderr
    assert "does not serve the cell file's cell 'othercell'" in run.stderr
    assert "it serves testcell: alice, bob" in run.stderr


async def test_ctrl_c_cancels_the_running_cell_goal_and_the_robots_stop(
    recorded: tuple[Path, Path, Recorder], capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C is what ``asyncio.run`` does with it: a cancel of the command's task, here while the
    replay's cell goal moves alice and bob."""
    from urdaemon.cli.parser import build_parser
    from urdaemon.replay import command as replay_command
    from urdaemon.replay.source import read_cell

    config, recording, _original = recorded
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        results = client.subscribe(f"{CELL}/goal/*/result")
        args = build_parser().parse_args(
            ["replay", str(recording), "--config", str(config), "--connect", client.endpoint, "--rate", "0.5"]
        )
        assert replay_command._bad_arguments(args) is None
        task = asyncio.ensure_future(replay_command._drive(args, read_cell(recording)))
        alice = next(rt for rt in daemon.runtimes if rt.robot.name == "alice").controller
        moved = client.subscribe(f"{CELL}/alice/goal/*/result")
        _key, payload = await moved.get(timeout=30.0)  # the move to the start ended
        move_goal = json.loads(payload)["goal_id"]
        for _ in range(2000):  # then the cell goal's part runs
            if alice.active_goal_id not in (None, move_goal):
                break
            await asyncio.sleep(0.005)
        assert alice.active_goal_id not in (None, move_goal)
        task.cancel()  # Ctrl-C
        code = await asyncio.wait_for(task, 30)
        _key, payload = await results.get(timeout=10.0)
        assert json.loads(payload)["status"] == "canceled"
        assert all(rt.controller.active_goal_id is None for rt in daemon.runtimes)
    assert code == 130
    err = capsys.readouterr().err
    assert "interrupted: canceling cell goal" in err
    assert "interrupted: the robots stop" in err
