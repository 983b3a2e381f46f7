"""The fake arm's surroundings (fakeur/contact.py): walls and a push, the TCP wrench, force mode,
freedrive and tool contact, through the URScript builtins that drive them.

Before the model (f5f0e26) the fake arm moved in free air: its TCP force was always zero, force mode and
freedrive moved nothing and ``tool_contact`` always answered 0 (this file fails there at its import, and
every behaviour it checks was absent: see tests/ur/test_ur_contact.py for the same gaps seen through
the daemon).
"""

from __future__ import annotations

import math

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.arm import HISTORY_STEPS, FakeArm
from urdaemon.fakeur.contact import (
    FORCE_LIMIT_N,
    TOOL_CONTACT_THRESHOLD_N,
    Surroundings,
    Wall,
    surroundings_of,
)
from urdaemon.fakeur.reports import output_getter, realtime_state, robot_state
from urdaemon.fakeur.urscript import lib_config as cfg
from urdaemon.fakeur.urscript.host import ScriptHost
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrPose
from urdaemon.model import SafetyMode
from urdaemon.protocols import primary as prim

E_SERIES_DT = 0.002
CB3_DT = 0.008


def _host(dt: float = E_SERIES_DT) -> ScriptHost:
    model = load_ur_model("ur10e")
    return ScriptHost(FakeArm(model, model.dh, powered=True), step_time=dt)


def _xyz(arm: FakeArm) -> tuple[float, float, float]:
    pose = arm.actual_tcp_pose()
    return (pose[0], pose[1], pose[2])


def _wall_below(arm: FakeArm, gap: float, stiffness: float = 20_000.0) -> Wall:
    x, y, z = _xyz(arm)
    wall = Wall.of((x, y, z - gap), (0.0, 0.0, 1.0), stiffness)
    surroundings_of(arm).walls.append(wall)
    return wall


def test_a_wall_pushes_back_in_proportion_to_depth_and_zero_ftsensor_removes_the_offset() -> None:
    host = _host()
    arm = host.arm
    wall = _wall_below(arm, -0.001)  # the tool is 1 mm inside
    arm.step(E_SERIES_DT)
    assert arm.tcp_force == pytest.approx([0.0, 0.0, 20.0, 0.0, 0.0, 0.0])
    assert wall.depth(_xyz(arm)) == pytest.approx(0.001)
    # every report reads it
    getter = output_getter("actual_TCP_force", "VECTOR6D", None)  # type: ignore[arg-type]
    assert getter(arm) == pytest.approx((0.0, 0.0, 20.0, 0.0, 0.0, 0.0))
    assert realtime_state(arm).tcp_force[2] == pytest.approx(20.0)
    state = robot_state(arm, arm.model, (5, 15, 0, 0))
    force = state.get(prim.ForceModeData)
    assert force is not None
    assert force.wrench[2] == pytest.approx(20.0)
    cfg.zero_ftsensor(host)
    surroundings_of(arm).push[0] = 5.0
    arm.step(E_SERIES_DT)
    assert arm.tcp_force == pytest.approx([5.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_a_free_arm_without_surroundings_reads_no_force_and_no_contact() -> None:
    host = _host()
    arm = host.arm
    arm.step(E_SERIES_DT)
    assert arm.surroundings is None
    assert arm.tcp_force == [0.0] * 6
    assert cfg.tool_contact(host, [0, 0, -0.1, 0, 0, 0]) == 0
    cfg.zero_ftsensor(host)  # nothing to remove
    assert arm.surroundings is None


def test_a_wall_protective_stops_a_position_move_beyond_the_force_limit() -> None:
    """A speedj into a wall: the force rises with depth, and past the limit the arm protective-stops."""
    arm = _host().arm
    wall = _wall_below(arm, 0.002)
    twist = [0.0, 0.0, -0.05, 0.0, 0.0, 0.0]
    arm.speedj(arm.ik.joint_velocity(arm.q, twist))
    peak = 0.0
    for _ in range(2000):
        arm.step(E_SERIES_DT)
        peak = max(peak, arm.tcp_force[2])
        if arm.safety_mode is SafetyMode.PROTECTIVE_STOP:
            break
    assert arm.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert FORCE_LIMIT_N < peak < FORCE_LIMIT_N + 0.05 * E_SERIES_DT * wall.stiffness * 2


@pytest.mark.parametrize("dt", [E_SERIES_DT, CB3_DT], ids=["e-series", "cb3"])
def test_force_mode_presses_into_a_wall_until_it_pushes_back_the_commanded_force(dt: float) -> None:
    host = _host(dt)
    arm = host.arm
    wall = _wall_below(arm, 0.005)
    start = _xyz(arm)
    frame = UrPose([0.0] * 6)
    cfg.force_mode(host, frame, [0, 0, 1, 0, 0, 0], [0.0, 0.0, -30.0, 0.0, 0.0, 0.0], 2, [0.1] * 6)
    peak_speed = 0.0
    for _ in range(round(2.0 / dt)):
        before = _xyz(arm)[2]
        arm.step(dt)
        peak_speed = max(peak_speed, abs(_xyz(arm)[2] - before) / dt)
        assert arm.safety_mode is SafetyMode.NORMAL
    assert arm.tcp_force[2] == pytest.approx(30.0, abs=0.1)
    assert wall.depth(_xyz(arm)) == pytest.approx(30.0 / wall.stiffness, abs=1e-5)
    x, y, _ = _xyz(arm)
    assert math.hypot(x - start[0], y - start[1]) < 1e-5, "the non-compliant axes did not move"
    assert peak_speed <= 0.1 + 1e-6, "the limit caps the compliant speed"
    cfg.end_force_mode(host)
    resting = list(arm.q)
    arm.step(dt)
    assert arm.q == resting, "out of force mode the wall's force moves nothing"


def test_force_mode_in_free_air_moves_at_its_speed_limit_in_the_task_frame() -> None:
    """A task frame turned 90 degrees about z: its x is the base's y; 10 N along it moves the TCP along
    base y at the admittance speed, capped at the limit."""
    host = _host()
    arm = host.arm
    start = _xyz(arm)
    turned = UrPose([0.0, 0.0, 0.0, 0.0, 0.0, math.pi / 2])
    cfg.force_mode(host, turned, [1, 0, 0, 0, 0, 0], [10.0, 0, 0, 0, 0, 0], 2, [0.02, 0.1, 0.1, 1, 1, 1])
    for _ in range(250):
        arm.step(E_SERIES_DT)
    moved = [a - b for a, b in zip(_xyz(arm), start, strict=True)]
    assert moved[1] == pytest.approx(0.02 * 0.5, rel=0.15)
    assert abs(moved[0]) < 1e-4
    assert abs(moved[2]) < 1e-4


def test_force_mode_types_that_follow_the_tcp_are_refused_as_not_simulated() -> None:
    host = _host()
    for kind in (1, 3):
        with pytest.raises(ScriptRuntimeError, match="not simulated"):
            cfg.force_mode(host, UrPose([0.0] * 6), [0, 0, 1, 0, 0, 0], [0] * 6, kind, [0.1] * 6)
    assert host.arm.force_mode is False


def test_freedrive_follows_a_push_along_free_axes_only_within_joint_limits_and_stops_without_it() -> None:
    host = _host()
    arm = host.arm
    surroundings = surroundings_of(arm)
    surroundings.push[:] = [20.0, 0.0, 20.0, 0.0, 0.0, 0.0]
    start = _xyz(arm)
    arm.step(E_SERIES_DT)
    assert _xyz(arm) == start, "not in freedrive: the push moves nothing"
    cfg.freedrive_mode(host, [1, 1, 0, 0, 0, 0])  # z is not free
    for _ in range(100):
        arm.step(E_SERIES_DT)
    moved = [a - b for a, b in zip(_xyz(arm), start, strict=True)]
    assert moved[0] == pytest.approx(20.0 * 0.005 * 0.2, rel=0.05)
    assert abs(moved[2]) < 1e-4
    surroundings.push[:] = [1e6, 0.0, 0.0, 0.0, 0.0, 0.0]  # a shove: the joints stay within their limits
    arm.step(E_SERIES_DT)
    assert max(abs(v) / limit for v, limit in zip(arm.qd, arm.max_velocity, strict=True)) == pytest.approx(
        1.0
    )
    surroundings.push[:] = [0.0] * 6
    arm.step(E_SERIES_DT)
    still = list(arm.q)
    for _ in range(10):
        arm.step(E_SERIES_DT)
    assert arm.q == still
    assert not any(arm.qd)


def test_tool_contact_counts_back_to_just_before_the_force_rose() -> None:
    host = _host()
    arm = host.arm
    wall = _wall_below(arm, 0.001)
    twist = [0.0, 0.0, -0.05, 0.0, 0.0, 0.0]
    down = [0.0, 0.0, -0.05, 0.0, 0.0, 0.0]
    steps = 0
    for _ in range(200):  # a slow approach, as a program would poll once per cycle
        arm.speedj(arm.ik.joint_velocity(arm.q, twist), 100.0)
        arm.step(E_SERIES_DT)
        steps = cfg.tool_contact(host, down)
        if steps:
            break
    assert steps > 1, "the force had to rise past the threshold over a few cycles"
    assert arm.tcp_force[2] > TOOL_CONTACT_THRESHOLD_N
    assert wall.depth(_xyz(arm)) > 0
    touched = arm.history(steps)
    inside = arm.history(steps - 1)
    assert wall.depth(arm.kinematics.tool_pose(touched)[:3]) == 0.0, "just before the contact"
    assert wall.depth(arm.kinematics.tool_pose(inside)[:3]) > 0.0, "the first cycle of the contact"
    # a contact from a direction the tool does not move in is not one; any direction when none is given
    assert cfg.tool_contact(host, [0.0, 0.0, 0.05, 0, 0, 0]) == 0
    assert cfg.tool_contact(host, [0.0] * 6) == steps
    assert cfg.tool_contact(host, down, 1000.0) == 0, "a threshold above the force"
    assert steps < HISTORY_STEPS


def test_surroundings_without_anything_are_idle() -> None:
    surroundings = Surroundings()
    seen = [surroundings.idle]
    surroundings.walls.append(Wall.of((0, 0, 0), (0, 0, 2)))
    assert surroundings.walls[0].normal == (0.0, 0.0, 1.0)
    seen.append(surroundings.idle)
    assert seen == [True, False]
    with pytest.raises(ValueError, match="normal"):
        Wall.of((0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="stiffness"):
        Wall.of((0, 0, 0), (0, 0, 1), -1.0)
