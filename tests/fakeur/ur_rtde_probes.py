"""One probe per ``RTDEControlInterface`` method: a sane call against the fake and a check of its effect.

A probe raises (AssertionError, or whatever ur_rtde raises) when the call does not do what ur_rtde
documents. :class:`Probe` holds what the probes share: ur_rtde's control and receive interfaces on one
fake, and our own kinematics to judge the results by. The runner (test_ur_rtde_full_api.py) also fails a
call after which the fake's primary interface reported a runtime error, or ur_rtde's script stopped
when the probe did not mean to stop it.

Probes of the motion calls are in ur_rtde_motion_probes.py; PROBES here is the union.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from tests.fakeur.judges import FakeProcess, PrimaryWatch, pose_off, tcp_pose, wait_until

__all__ = ["HOME", "QUERY_PROBES", "Probe", "ProbeFn", "near"]

HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
"""The fake arm's joints when it starts (urdaemon/fakeur/fake_arm.py)."""
JOINT_TOL = 1e-3
STILL = 1e-6
TCP = [0.01, -0.02, 0.12, 0.0, 0.0, 0.3]
"""A TCP offset the query group sets, so flange and TCP poses differ."""


@dataclass
class Probe:
    """ur_rtde's interfaces on one fake, what the probes share."""

    fake: FakeProcess
    primary: PrimaryWatch
    receiver: Any
    control: Any
    rate: float
    make_control: Callable[[], Any]
    script_ended: bool = False
    """Set by a probe whose call ends ur_rtde's script on purpose (stopScript, the watchdog)."""
    tcp: list[float] = field(default_factory=lambda: [0.0] * 6)

    @property
    def model(self) -> str:
        return self.fake.model

    def q(self) -> list[float]:
        return list(self.receiver.getActualQ())

    def pose(self) -> list[float]:
        return list(self.receiver.getActualTCPPose())

    def at_rest(self) -> bool:
        return bool(max(abs(v) for v in self.receiver.getActualQd()) < STILL)

    def settle(self, states: int = 2) -> None:
        """Wait for ``states`` more primary robot states (10 Hz): a runtime error the call caused has
        arrived by then, as the controller sends messages in order."""
        self.primary.wait_for_state(states, 10.0)

    def rest(self, seconds: float = 10.0) -> None:
        assert wait_until(self.at_rest, seconds), f"still moving: {list(self.receiver.getActualQd())}"

    def cycles(self, count: int) -> None:
        """Wait until rtde_receive saw ``count`` more controller cycles (bounded)."""
        start = self.receiver.getTimestamp()
        assert wait_until(lambda: self.receiver.getTimestamp() >= start + count / self.rate, 10.0)

    def reached_q(self, target: Sequence[float]) -> None:
        assert wait_until(lambda: near(self.q(), target, JOINT_TOL) and self.at_rest(), 15.0), (
            f"joints {self.q()}, target {list(target)}"
        )

    def reached_pose(self, target: Sequence[float], tol: float = 1e-4) -> None:
        assert wait_until(lambda: not pose_off(self.pose(), target, tol, 1e-3) and self.at_rest(), 15.0), (
            pose_off(self.pose(), target, tol, 1e-3)
        )

    def second(self, call: Callable[[], Any]) -> Any:
        """ur_rtde returns the realtime queries (getStepTime, getJointTorques, and the dynamics getters its
        script lists as realtime: getMassMatrix, getJacobian...) without waiting for the script: the
        registers it reads are the previous call's. Call, let the script answer, call again."""
        call()
        self.cycles(5)
        return call()


ProbeFn = Callable[[Probe], None]


def near(actual: Sequence[float], target: Sequence[float], tol: float) -> bool:
    return len(actual) == len(target) and max(abs(a - b) for a, b in zip(actual, target, strict=True)) <= tol


def ok(result: object, call: str) -> None:
    assert result is True, f"{call} returned {result!r}"


def _off(actual: Sequence[float], target: Sequence[float]) -> None:
    off = pose_off(list(actual), target)
    assert not off, off


# ---- the query group: no motion ------------------------------------------------------------------------


def _status(p: Probe) -> None:
    status = p.control.getRobotStatus()
    assert status & 0b11 == 0b11, f"getRobotStatus {status:#b}: power on and program running expected"


def _inverse_kinematics(p: Probe) -> None:
    known = [0.2, -1.3, 1.4, -1.6, -1.5, 0.3]
    q = list(p.control.getInverseKinematics(list(tcp_pose(p.model, known, p.tcp)), [v + 0.05 for v in known]))
    assert near(q, known, JOINT_TOL), f"the branch nearest qnear is {known}, got {q}"


def _has_solution(p: Probe) -> None:
    ok(p.control.getInverseKinematicsHasSolution(list(tcp_pose(p.model, HOME, p.tcp))), "reachable")
    far = [5.0, 0.0, 0.5, 0.0, math.pi, 0.0]
    assert p.control.getInverseKinematicsHasSolution(far) is False, "a pose 5 m away has no solution"


def _forward_kinematics(p: Probe) -> None:
    _off(p.control.getForwardKinematics(), tcp_pose(p.model, p.q(), p.tcp))
    known, tcp = [0.2, -1.3, 1.4, -1.6, -1.5, 0.3], [0.0, 0.02, 0.1, 0.0, 0.2, 0.0]
    _off(p.control.getForwardKinematics(known, tcp), tcp_pose(p.model, known, tcp))


def _set_tcp(p: Probe) -> None:
    ok(p.control.setTcp(TCP), "setTcp")
    p.tcp = list(TCP)
    assert wait_until(lambda: not pose_off(p.pose(), tcp_pose(p.model, p.q(), TCP)), 10.0), (
        f"getActualTCPPose {p.pose()} does not show TCP {TCP}"
    )


def _tcp_offset(p: Probe) -> None:
    assert near(p.control.getTCPOffset(), p.tcp, 1e-9), f"{list(p.control.getTCPOffset())} != {p.tcp}"


def _flange_pose(p: Probe) -> None:
    # the registers hold the TCP offset now (getTCPOffset ran last): a stale answer shows
    _off(p.second(p.control.getActualToolFlangePose), tcp_pose(p.model, p.q()))


def _target_waypoint(p: Probe) -> None:
    _off(p.control.getTargetWaypoint(), list(p.receiver.getTargetTCPPose()))


def _target_accelerations(p: Probe) -> None:
    p.control.getForwardKinematics()  # non-zero registers, so a stale answer shows
    accelerations = list(p.second(p.control.getTargetJointAccelerations))
    assert near(accelerations, [0.0] * 6, 1e-9), f"at rest: {accelerations}"


def _pose_trans(p: Probe) -> None:
    result = p.control.poseTrans([0.1, 0.0, 0.0, 0.0, 0.0, math.pi / 2], [0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    _off(result, [0.1, 0.1, 0.0, 0.0, 0.0, math.pi / 2])


def _joints_within_limits(p: Probe) -> None:
    ok(p.control.isJointsWithinSafetyLimits(p.q()), "isJointsWithinSafetyLimits(current)")
    outside = [7.0, *p.q()[1:]]  # beyond the +-2 pi of every e-Series joint
    assert p.control.isJointsWithinSafetyLimits(outside) is False, "7 rad on the base is beyond its limit"


def _pose_within_limits(p: Probe) -> None:
    ok(p.control.isPoseWithinSafetyLimits(p.pose()), "isPoseWithinSafetyLimits(current)")


def _payload(p: Probe) -> None:
    ok(p.control.setPayload(1.5, [0.0, 0.01, 0.05]), "setPayload")
    assert wait_until(
        lambda: (
            abs(p.receiver.getPayload() - 1.5) < 1e-9
            and near(p.receiver.getPayloadCog(), [0.0, 0.01, 0.05], 1e-9)
        ),
        10.0,
    ), f"payload {p.receiver.getPayload()} cog {list(p.receiver.getPayloadCog())}"


def _target_payload(p: Probe) -> None:
    ok(
        p.control.setTargetPayload(1.2, [0.0, 0.0, 0.04], [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]),
        "setTargetPayload",
    )
    assert wait_until(
        lambda: (
            abs(p.receiver.getPayload() - 1.2) < 1e-9
            and near(p.receiver.getPayloadCog(), [0.0, 0.0, 0.04], 1e-9)
        ),
        10.0,
    ), f"payload {p.receiver.getPayload()} cog {list(p.receiver.getPayloadCog())}"


def _async_progress(p: Probe) -> None:
    assert p.control.getAsyncOperationProgress() < 0, "no asynchronous operation runs"


def _async_progress_ex(p: Probe) -> None:
    assert not p.control.getAsyncOperationProgressEx().isAsyncOperationRunning()


def _periods(p: Probe) -> None:
    start = p.control.initPeriod()
    assert isinstance(start, datetime.timedelta)
    p.control.waitPeriod(start)


QUERY_PROBES: dict[str, ProbeFn] = {
    "isConnected": lambda p: ok(p.control.isConnected(), "isConnected"),
    "isProgramRunning": lambda p: ok(p.control.isProgramRunning(), "isProgramRunning"),
    "getRobotStatus": _status,
    "isSteady": lambda p: ok(p.control.isSteady(), "isSteady at rest"),
    "getInverseKinematics": _inverse_kinematics,
    "getInverseKinematicsHasSolution": _has_solution,
    "getForwardKinematics": _forward_kinematics,
    "setTcp": _set_tcp,
    "getTCPOffset": _tcp_offset,
    "getActualToolFlangePose": _flange_pose,
    "getTargetWaypoint": _target_waypoint,
    "getTargetJointAccelerations": _target_accelerations,
    "poseTrans": _pose_trans,
    "isJointsWithinSafetyLimits": _joints_within_limits,
    "isPoseWithinSafetyLimits": _pose_within_limits,
    "setGravity": lambda p: ok(p.control.setGravity([0.0, 0.0, 9.82]), "setGravity"),
    "setPayload": _payload,
    "setTargetPayload": _target_payload,
    "getFreedriveStatus": lambda p: ok(p.control.getFreedriveStatus() == 0, "getFreedriveStatus() == 0"),
    "getAsyncOperationProgress": _async_progress,
    "getAsyncOperationProgressEx": _async_progress_ex,
    "initPeriod": _periods,
    "waitPeriod": _periods,
    "getStepTime": lambda p: ok(p.second(p.control.getStepTime) == 1 / p.rate, "getStepTime() == 1/rate"),
    "getActualJointPositionsHistory": lambda p: ok(
        near(p.second(lambda: p.control.getActualJointPositionsHistory(0)), p.q(), 1e-6), "history(0) == q"
    ),
    "getJointTorques": lambda p: ok(
        near(p.second(p.control.getJointTorques), [0.0] * 6, 1.0), "corrected torques ~0 at rest"
    ),
    "toolContact": lambda p: ok(p.second(lambda: p.control.toolContact([0.0] * 6)) == 0, "no contact"),
}
