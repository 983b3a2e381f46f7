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
from urdaemon.fakeur.contact import (
    FORCE_LIMIT_N,
    TOOL_CONTACT_THRESHOLD_N,
    Surroundings,
    Wall,
    surroundings_of,
)
from urdaemon.fakeur.fake_arm import HISTORY_STEPS, FakeArm
from urdaemon.fakeur.reports import output_getter, realtime_state, robot_state
from urdaemon.fakeur.urscript import lib_config as cfg
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrPose
from urdaemon.fakeur.urscript.script_host import ScriptHost
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
    touched = arm.history.ago(steps)
    inside = arm.history.ago(steps - 1)
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


def _approach_until_contact(host: ScriptHost, direction: list[float]) -> int:
    """Drive the TCP along ``direction`` (m/s, base frame) polling ``tool_contact`` once a cycle."""
    arm = host.arm
    for _ in range(400):
        arm.speedj(arm.ik.joint_velocity(arm.q, direction), 100.0)
        arm.step(E_SERIES_DT)
        steps: int = cfg.tool_contact(host, direction)
        if steps:
            return steps
    raise AssertionError("no contact within 400 cycles")


@pytest.mark.parametrize("zeroed", [True, False], ids=["zeroed", "not-zeroed"])
def test_tool_contact_counts_from_the_touch_not_from_a_steady_force_felt_before(zeroed: bool) -> None:
    """A steady 2 N on the tool (a payload mismatch, a cable), zeroed or not, standing 1.2 s, then a
    touch of a wall: the contact started at the touch. On 0dd9381 the count ran from when the steady
    force began (about 615 cycles instead of about 4), and a program that moves back by it went to a
    pose from 1.2 s before."""
    host = _host()
    arm = host.arm
    surroundings = surroundings_of(arm)
    surroundings.push[:] = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    arm.step(E_SERIES_DT)
    if zeroed:
        cfg.zero_ftsensor(host)
    for _ in range(600):
        arm.step(E_SERIES_DT)
    wall = _wall_below(arm, 0.001)
    steps = _approach_until_contact(host, [0.0, 0.0, -0.05, 0.0, 0.0, 0.0])
    assert 1 < steps < 20
    touched, inside = arm.history.ago(steps), arm.history.ago(steps - 1)
    assert wall.depth(arm.kinematics.tool_pose(touched)[:3]) == 0.0, "just before the contact"
    assert wall.depth(arm.kinematics.tool_pose(inside)[:3]) > 0.0, "the first cycle of the contact"


def test_tool_contact_without_a_wall_starts_where_the_force_rises_beyond_its_zeroed_level() -> None:
    """Resting on a table with the sensor zeroed, then a hand presses the tool down: the contact
    starts at the press. On 0dd9381 it dated from the table's first touch, 500 cycles earlier."""
    host = _host()
    arm = host.arm
    _wall_below(arm, -0.0005)  # the tool rests 0.5 mm into a table: 10 N
    surroundings = surroundings_of(arm)
    arm.step(E_SERIES_DT)
    cfg.zero_ftsensor(host)
    for _ in range(500):
        arm.step(E_SERIES_DT)
    assert cfg.tool_contact(host, [0.0] * 6) == 0, "resting, zeroed: no contact"
    surroundings.push[:] = [0.0, 0.0, 3.0, 0.0, 0.0, 0.0]  # the tool held still, pressed from below
    arm.step(E_SERIES_DT)
    assert cfg.tool_contact(host, [0.0] * 6) == 0, "below the threshold"
    for press in (6.0, 9.0):
        surroundings.push[2] = press
        arm.step(E_SERIES_DT)
    assert cfg.tool_contact(host, [0.0, 0.0, -0.05, 0, 0, 0]) == 3, "counted from the first rise"


@pytest.mark.parametrize(
    ("dt", "stiffness"),
    [(E_SERIES_DT, 2e5), (E_SERIES_DT, 1e7), (CB3_DT, 5e4), (CB3_DT, 1e7)],
    ids=["e-series-bound", "e-series-beyond", "cb3-bound", "cb3-beyond"],
)
def test_freedrive_pushed_into_a_wall_of_any_stiffness_comes_to_rest(dt: float, stiffness: float) -> None:
    """A hand pushes the freedriven tool 20 N into a wall: it sinks in until the wall pushes back 20 N
    and stops. On 0dd9381 the admittance was stepped explicitly against the wall: at a loop gain
    ``dt * 0.005 * stiffness`` of 2 (2e5 N/m at 2 ms, 5e4 N/m at CB3's 8 ms, the bound our docs gave)
    the force swung -20..+20 N forever, and beyond it the first cycle's sink tripped a protective stop."""
    host = _host(dt)
    arm = host.arm
    wall = _wall_below(arm, 0.0, stiffness)
    surroundings_of(arm).push[:] = [0.0, 0.0, -20.0, 0.0, 0.0, 0.0]
    cfg.freedrive_mode(host)
    felt = []
    for _ in range(round(0.5 / dt)):
        arm.step(dt)
        felt.append(arm.tcp_force[2])
        assert arm.safety_mode is SafetyMode.NORMAL
    assert max(abs(f) for f in felt[-10:]) < 0.01, "the wall balances the push"
    assert max(abs(v) for v in arm.qd) < 1e-6, "at rest"
    assert wall.depth(_xyz(arm)) == pytest.approx(20.0 / stiffness, rel=1e-3)


@pytest.mark.parametrize(
    ("dt", "stiffness"),
    [(E_SERIES_DT, 1e8), (CB3_DT, 1e6), (CB3_DT, 1e8)],
    ids=["e-series", "cb3", "cb3-stiffer"],
)
def test_force_mode_against_a_stiff_wall_settles_at_the_commanded_force(dt: float, stiffness: float) -> None:
    """Force mode pressing 30 N into a wall far stiffer than the 1e5 / 5e4 N/m our docs allowed, the
    tool starting at its surface: the force settles at 30 N. On 0dd9381 (explicit against the wall) the
    first cycle's sink tripped a protective stop, or at CB3's 8 ms into 1e6 N/m the force kept
    swinging."""
    host = _host(dt)
    arm = host.arm
    _wall_below(arm, 0.0, stiffness)
    cfg.force_mode(host, UrPose([0.0] * 6), [0, 0, 1, 0, 0, 0], [0.0, 0.0, -30.0, 0, 0, 0], 2, [0.1] * 6)
    felt = []
    for _ in range(round(2.0 / dt)):
        arm.step(dt)
        felt.append(arm.tcp_force[2])
        assert arm.safety_mode is SafetyMode.NORMAL
    assert felt[-10:] == pytest.approx([30.0] * 10, abs=0.05)
    assert max(felt) < FORCE_LIMIT_N


def test_with_nothing_around_the_arm_a_step_reallocates_nothing_and_still_sees_changes() -> None:
    """After freedrive has come and gone (the arm keeps its surroundings) and with nothing around it, a
    step only counts the cycle: the reported force is the same object cycle after cycle (on 0dd9381 each
    step built a new force list, wrench and twist). A push, a wall or ``zero_ftsensor`` is seen at once."""
    host = _host()
    arm = host.arm
    cfg.freedrive_mode(host)
    cfg.end_freedrive_mode(host)
    surroundings = surroundings_of(arm)
    arm.step(E_SERIES_DT)
    reported = arm.tcp_force
    for _ in range(5):
        arm.step(E_SERIES_DT)
    assert arm.tcp_force is reported
    assert reported == [0.0] * 6
    surroundings.push[0] = 3.0
    arm.step(E_SERIES_DT)
    assert arm.tcp_force[0] == 3.0
    cfg.zero_ftsensor(host)
    arm.step(E_SERIES_DT)
    assert arm.tcp_force[0] == 0.0
    surroundings.push[0] = 0.0  # the zeroed push lets go: the tool feels its absence
    arm.step(E_SERIES_DT)
    released = arm.tcp_force
    arm.step(E_SERIES_DT)
    assert arm.tcp_force is released
    assert released[0] == -3.0
    cfg.zero_ftsensor(host)
    arm.step(E_SERIES_DT)
    assert arm.tcp_force[0] == 0.0, "zeroing is seen with nothing around"
    _wall_below(arm, -0.001)
    arm.step(E_SERIES_DT)
    assert arm.tcp_force[2] == pytest.approx(20.0)
