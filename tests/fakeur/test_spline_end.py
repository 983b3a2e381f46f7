"""A fast spline ends on its last point when its SUCCESS is sent (issue 33, point 7).

urcl's External Control script follows a spline segment open loop: from ``get_joint_positions()`` it
integrates the polynomial's velocity with one ``speedj(qd, qdd_max, step)`` a cycle (the acceleration
chosen so the change fits in the step), ends the segment with a step shorter than a cycle, and after the
last point runs ``stopj(4.0)`` and sends TRAJECTORY_RESULT_SUCCESS. Its URSim tests
(``test_spline_interpolation.cpp``, ``zero_time_trajectory_*``) expect ``target_q`` within 0.02 rad of
the last point then, after a 1 s segment that asks some joints for more than their speed limit.

The follower below is our own minimal one doing the same on the trajectory socket (our codec sends the
points, as urcl's ``writeTrajectorySplinePoint`` does). On the old fake, ``speedj`` clamped each joint
to its limit on its own, so the arm fell behind and off the path: SUCCESS came with ``target_q`` 0.18 rad
from the last point. A controller slows the program's time to stay within the joint speed limits, so the
path and the distance are kept (docs/fake-robot.md, "Errors, stops and safety").
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

import pytest

from tests.fakeur.control_rig import HOME, TRAJ, ZERO, Daemon, Rig, make_arm
from urdaemon.protocols._fixed import MULT
from urdaemon.protocols.trajectory_point import SplinePoint, TrajectoryResultCode

pytestmark = pytest.mark.timeout(60)

URCL_EPS = 0.02
"""rad: how near urcl's spline tests require the arm to its target."""
FAR = (-1.6, -1.72, -2.175, -0.78, 1.623, -0.5)
"""The second point of urcl's ``zero_time_trajectory_*`` tests, 1 s after the first."""
BACK = (*HOME[:5], HOME[5] + 0.1)
"""Its third point: where the arm started, wrist 3 turned by 0.1 rad, 2 s later."""

FOLLOWER = """def spline_follower():
  socket_open("127.0.0.1", {port}, "trajectory_socket")
  global spline_qd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
  global spline_qdd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
  def largest(v):
    local m = norm(v[0])
    local i = 1
    while i < 6:
      if norm(v[i]) > m:
        m = norm(v[i])
      end
      i = i + 1
    end
    return m
  end
  def push(c1, c2, c3, c4, c5, s, dt):
    local before = spline_qd
    spline_qd = c1 + 2.0 * s * c2 + 3.0 * pow(s, 2) * c3 + 4.0 * pow(s, 3) * c4 + 5.0 * pow(s, 4) * c5
    spline_qdd = 2.0 * c2 + 6.0 * s * c3 + 12.0 * pow(s, 2) * c4 + 20.0 * pow(s, 3) * c5
    speedj(spline_qd, largest((spline_qd - before) / dt), dt)
  end
  def segment(q1, v1, a1, T, quintic):
    local q0 = get_joint_positions()
    local v0 = spline_qd
    local a0 = spline_qdd
    local T2 = pow(T, 2)
    local c2 = (3.0 * (q1 - q0) - 2.0 * v0 * T - v1 * T) / T2
    local c3 = (2.0 * (q0 - q1) + v0 * T + v1 * T) / pow(T, 3)
    local c4 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    local c5 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    if quintic:
      c2 = 0.5 * a0
      c3 = (20.0 * (q1 - q0) - 3.0 * a0 * T2 + a1 * T2 - 12.0 * v0 * T - 8.0 * v1 * T) / (2.0 * pow(T, 3))
      c4 = 30.0 * (q0 - q1) + 3.0 * a0 * T2 - 2.0 * a1 * T2 + 16.0 * v0 * T + 14.0 * v1 * T
      c4 = c4 / (2.0 * pow(T, 4))
      c5 = (12.0 * (q1 - q0) - a0 * T2 + a1 * T2 - 6.0 * v0 * T - 6.0 * v1 * T) / (2.0 * pow(T, 5))
    end
    local s = 0.0
    while (T - s) > get_steptime():
      s = s + get_steptime()
      push(v0, c2, c3, c4, c5, s, get_steptime())
    end
    push(v0, c2, c3, c4, c5, T, T - s)
  end
  left = {count}
  while left > 0:
    raw = socket_read_binary_integer(21, "trajectory_socket", 0.5)
    left = left - 1
    point = [raw[1], raw[2], raw[3], raw[4], raw[5], raw[6]] / {mult}
    speed = [raw[7], raw[8], raw[9], raw[10], raw[11], raw[12]] / {mult}
    acceleration = [raw[13], raw[14], raw[15], raw[16], raw[17], raw[18]] / {mult}
    segment(point, speed, acceleration, raw[19] / {mult}, raw[20] == 2)
    if raw[20] == 1:
      spline_qdd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    end
  end
  stopj(4.0)
  socket_send_int(0, "trajectory_socket")
  socket_read_binary_integer(1, "trajectory_socket", 60.0)
end
"""


@asynccontextmanager
async def _follower(count: int) -> AsyncIterator[Rig]:
    daemon = Daemon()
    await daemon.serve(TRAJ)
    rig = Rig(daemon, make_arm("ur10e"), FOLLOWER.format(port=daemon.ports[TRAJ], count=count, mult=MULT))
    try:
        await rig.until(daemon.connected[TRAJ].is_set, 500)
        yield rig
    finally:
        if not rig.run.done:
            rig.run.stop()
        rig.host.close()
        await daemon.close()


async def _target_at_success(points: Sequence[SplinePoint]) -> tuple[list[float], Rig]:
    async with _follower(len(points)) as rig:
        rig.daemon.send_points(*points)
        result = await rig.result(max_cycles=10_000)
        assert result is TrajectoryResultCode.SUCCESS, rig.texts()
        return list(rig.arm.target_q), rig


@pytest.mark.parametrize("quintic", [False, True], ids=["cubic", "quintic"])
async def test_a_spline_too_fast_for_a_joint_ends_on_its_last_point(quintic: bool) -> None:
    accelerations = ZERO if quintic else None
    points = (SplinePoint(FAR, ZERO, accelerations, 1.0), SplinePoint(BACK, ZERO, accelerations, 2.0))
    target, rig = await _target_at_success(points)
    assert max(abs(a - b) for a, b in zip(target, BACK, strict=True)) < URCL_EPS, target
    limits = rig.arm.max_velocity
    for speeds in rig.speeds:  # slowed, never clamped past a joint's limit
        assert all(abs(v) <= limit + 1e-9 for v, limit in zip(speeds, limits, strict=True))


async def test_a_spline_within_the_limits_is_followed_in_its_own_time() -> None:
    """Within the joint limits nothing is slowed: the spline takes its segment times, to the cycle."""
    near = (0.3, -1.4, 1.2, -1.5, -1.3, 0.2)
    points = (SplinePoint(near, ZERO, None, 1.0), SplinePoint(BACK, ZERO, None, 1.0))
    target, rig = await _target_at_success(points)
    assert max(abs(a - b) for a, b in zip(target, BACK, strict=True)) < URCL_EPS, target
    assert rig.index_reached(BACK, tolerance=URCL_EPS) <= rig.first_motion() + round(2.0 / 0.002) + 1
