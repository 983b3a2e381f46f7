"""Motion and state builtins through small URScript programs, compiled and stepped like the controller."""

from __future__ import annotations

import math

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.model import SafetyMode

DT = 0.002
LIMIT = 20_000


def _run(text: str, *, slider: float = 1.0) -> tuple[ScriptHost, list[tuple[str, str]], int]:
    """Compile and run ``text`` to its end: program step, then arm step, once per cycle."""
    model = load_ur_model("ur10e")
    arm = FakeArm(model, model.dh, powered=True)
    arm.start_program()
    arm.speed_slider = slider
    messages: list[tuple[str, str]] = []
    host = ScriptHost(arm, step_time=DT, message=lambda kind, text: messages.append((kind, text)))
    run = compile_program(text, series="e", version=(5, 12)).start(host)
    cycles = 0
    while not run.done and cycles < LIMIT:
        run.step()
        arm.step(DT)
        cycles += 1
    assert run.done, "the program never ended"
    assert run.error is None, run.error
    return host, messages, cycles


def test_a_bare_urx_style_movej_line_runs_to_its_target() -> None:
    host, _, cycles = _run("movej([0.5, -1.2, 1.4, -1.6, -1.5, 0.3], a=1.4, v=1.05)\n")
    assert host.arm.q == pytest.approx([0.5, -1.2, 1.4, -1.6, -1.5, 0.3], abs=1e-3)
    assert cycles > 100


def test_movel_then_state_getters_in_a_program() -> None:
    text = """def move_and_report():
  start = get_actual_tcp_pose()
  movel(pose_add(start, p[0.05, 0.0, -0.05, 0.0, 0.0, 0.0]), a=1.2, v=0.25)
  here = get_actual_tcp_pose()
  textmsg("moved ", pose_dist(start, here))
  textmsg("steady ", is_steady())
  q = get_inverse_kin(here)
  textmsg("ik ", norm(q - get_actual_joint_positions()))
end
"""
    _, messages, _ = _run(text)
    moved = float(messages[0][1].split()[1])
    assert moved == pytest.approx(math.hypot(0.05, 0.05), abs=1e-4)
    assert messages[1] == ("text", "steady True")
    assert float(messages[2][1].split()[1]) < 1e-6


def test_the_speed_slider_halves_a_program_s_motion_speed() -> None:
    text = "movej([1.0, -1.57, 1.57, -1.57, -1.57, 0.0], a=1.4, v=1.05)\n"
    _, _, fast = _run(text)
    _, _, slow = _run(text, slider=0.5)
    assert slow == pytest.approx(2 * fast, abs=3)


def test_two_threads_commanding_motion_the_latest_command_wins() -> None:
    """A thread streams speedj while main issues a movej: no crash, the program ends at main's target."""
    text = """def two():
  thread spinner():
    while True:
      speedj([0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 2.0, 0.002)
    end
  end
  h = run spinner()
  sleep(0.1)
  kill h
  movej([0.3, -1.57, 1.57, -1.57, -1.57, 0.0], a=1.4, v=1.05)
end
"""
    host, _, _ = _run(text)
    assert host.arm.q == pytest.approx([0.3, -1.57, 1.57, -1.57, -1.57, 0.0], abs=1e-3)


def test_a_killed_moving_thread_leaves_the_arm_stopping() -> None:
    text = """def killer():
  thread mover():
    movej([2.0, -1.57, 1.57, -1.57, -1.57, 0.0], a=1.4, v=1.05)
  end
  h = run mover()
  sleep(0.5)
  kill h
  sleep(1.0)
  textmsg("speeds ", norm(get_actual_joint_speeds()))
end
"""
    host, messages, _ = _run(text)
    assert len(messages) == 1
    assert float(messages[0][1].split()[1]) == 0.0
    assert 0.1 < host.arm.q[0] < 1.0, "stopped short of the target"


def test_movej_out_of_the_joint_limits_is_a_runtime_error_and_movel_a_protective_stop() -> None:
    """A joint move's target is checked before it plans (the program stops, so urcl's trajectory ends
    with a failure); a straight move the arm cannot make protective-stops (fake-robot.md, "Errors")."""
    model = load_ur_model("ur10e")
    arm = FakeArm(model, model.dh, powered=True)
    arm.start_program()
    host = ScriptHost(arm, step_time=DT)
    limit = arm.max_position[0]
    run = compile_program(f"movej([{limit + 1.0}, -1.57, 1.57, -1.57, -1.57, 0.0])\n", series="e").start(host)
    run.step()
    arm.step(DT)
    assert "outside the joint limits" in str(run.error)
    safety = arm.safety_mode
    assert safety is SafetyMode.NORMAL
    run = compile_program(f"movel([{limit + 1.0}, -1.57, 1.57, -1.57, -1.57, 0.0])\n", series="e").start(host)
    run.step()
    arm.step(DT)
    safety = arm.safety_mode
    assert safety is SafetyMode.PROTECTIVE_STOP


SERVO_STEP = """def servo_step():
  target = get_actual_joint_positions()
  target[0] = target[0] + 0.1
  swings = 0
  side = -1
  peak = 0.0
  i = 0
  while i < 1000:
    servoj(target, t=0.002, lookahead_time={lookahead}, gain={gain})
    e = get_actual_joint_positions()[0] - target[0]
    if e > 0.0001 and side < 0:
      swings = swings + 1
      side = 1
    elif e < -0.0001 and side > 0:
      swings = swings + 1
      side = -1
    end
    if e > peak:
      peak = e
    end
    i = i + 1
  end
  textmsg("swings ", swings)
  textmsg("overshoot ", peak)
end
"""


def _servo_step(lookahead: float, gain: int) -> tuple[int, float]:
    """(times the joint swung past the setpoint by more than 0.1 mrad, peak overshoot in rad)."""
    _, messages, _ = _run(SERVO_STEP.format(lookahead=lookahead, gain=gain))
    texts = [text for _, text in messages]
    swings = [int(t.removeprefix("swings ")) for t in texts if t.startswith("swings ")]
    peaks = [float(t.removeprefix("overshoot ")) for t in texts if t.startswith("overshoot ")]
    assert len(swings) == 1, texts
    assert len(peaks) == 1, texts
    return swings[0], peaks[0]


def test_a_servoj_stream_with_low_gain_and_short_lookahead_oscillates_more() -> None:
    """A program holding a 0.1 rad step with servoj for 1000 cycles, counting in URScript how often the
    joint swings past the setpoint: the manual's gain/lookahead make 100 / 0.03 (damping ratio 0.15)
    ring for several swings and 300 / 0.1 (0.87) overshoot at most once, by about exp(-πζ/√(1-ζ²)).
    On f5f0e26 servoj reached the setpoint exactly in each call: no swing, no overshoot, either way."""
    ringing, ringing_peak = _servo_step(0.03, 100)
    damped, damped_peak = _servo_step(0.1, 300)
    assert ringing >= 4
    assert damped <= 1
    assert ringing > damped
    zeta = 0.5 * 0.03 * math.sqrt(100)
    assert ringing_peak == pytest.approx(
        0.1 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta)), rel=0.05
    )
    assert damped_peak < 0.01 * ringing_peak
