"""The examples run against a live daemon and do what they say."""

from __future__ import annotations

import pytest

from tests.helpers import in_thread, run_script
from tests.integration.conftest import ROOT, running_daemon
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(120)


async def _run_example(name: str, daemon: Daemon, *args: str) -> tuple[int, str]:
    """Run ``python examples/NAME --connect ENDPOINT ARGS`` in-process, in a thread of its own (the
    daemon in this loop keeps serving); its exit code and output."""
    endpoint = daemon.listen_endpoints[0]
    path = ROOT / "examples" / name
    run = await in_thread(lambda: run_script(path, "--connect", endpoint, *args), name, 90.0)
    return run.code, run.stdout + run.stderr


async def test_dual_arm_example_moves_both_arms_and_succeeds() -> None:
    text = (ROOT / "configs" / "dual_robot_mock.yaml").read_text()
    async with running_daemon(text) as (daemon, _):
        code, out = await _run_example("dual_arm.py", daemon)
        assert code == 0, out
        assert "alice: succeeded" in out
        assert "bob: succeeded" in out
        assert "alice home: succeeded" in out
        alice = daemon.runtimes[0].backend.state.positions
        assert alice == pytest.approx([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], abs=0.01)


async def test_jog_example_moves_the_base_and_the_deadman_stops_it() -> None:
    text = (ROOT / "configs" / "dual_robot_mock.yaml").read_text()
    async with running_daemon(text) as (daemon, _):
        before = daemon.runtimes[0].backend.state.positions[0]
        code, out = await _run_example("jog.py", daemon, "--seconds", "1.0", "--speed", "0.3")
        assert code == 0, out
        assert "at rest at" in out
        moved = daemon.runtimes[0].backend.state.positions[0] - before
        assert 0.2 < moved < 0.4, f"1 s at 0.3 rad/s (with ramps and the stop) moved {moved:.3f} rad"
