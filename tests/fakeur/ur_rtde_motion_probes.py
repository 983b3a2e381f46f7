"""Probes of ``RTDEControlInterface``'s motion, force, mode, dynamics and life-cycle calls (see
ur_rtde_probes.py for what a probe is). Motions are small (centimetres, tenths of a radian) near the
fake's home, and each ends at rest, so the next probe starts from a resting arm."""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import rtde_control

from tests.description.test_dynamics import GRAVITY, Reference
from tests.fakeur.judges import tcp_pose, wait_until
from tests.fakeur.ur_rtde_probes import Probe, ProbeFn, near, ok

__all__ = ["DYNAMICS_PROBES", "LIFE_PROBES", "MODE_PROBES", "MOTION_PROBES", "WALL_BELOW"]

WALL_BELOW = 0.04
"""m: the mode group's fake has a wall this far below the TCP at home (for moveUntilContact)."""


def _shifted(p: Probe, dq: tuple[float, ...]) -> list[float]:
    return [q + d for q, d in zip(p.q(), dq, strict=True)]


def _up(p: Probe, dz: float) -> list[float]:
    pose = p.pose()
    return [pose[0], pose[1], pose[2] + dz, *pose[3:]]


def _move_j(p: Probe) -> None:
    start = p.q()
    target = _shifted(p, (0.1, -0.1, 0.1, -0.1, 0.1, 0.1))
    ok(p.control.moveJ(target, 1.05, 1.4), "moveJ(q)")
    p.reached_q(target)
    ok(p.control.moveJ([[*start, 1.05, 1.4, 0.0]]), "moveJ(path)")
    p.reached_q(start)


def _move_l(p: Probe) -> None:
    target = _up(p, 0.03)
    ok(p.control.moveL(target, 0.25, 1.2), "moveL")
    p.reached_pose(target)


def _move_j_ik(p: Probe) -> None:
    target = _up(p, -0.03)
    ok(p.control.moveJ_IK(target, 1.05, 1.4), "moveJ_IK")
    p.reached_pose(target)


def _move_l_fk(p: Probe) -> None:
    target = _shifted(p, (0.05, 0.0, 0.0, 0.0, 0.0, 0.05))
    ok(p.control.moveL_FK(target, 0.25, 1.2), "moveL_FK")
    p.reached_q(target)


def _move_path(p: Probe) -> None:
    target = _shifted(p, (-0.05, 0.0, 0.0, 0.0, 0.0, -0.05))
    path = rtde_control.Path()
    path.addEntry(
        rtde_control.PathEntry(
            rtde_control.PathEntry.MoveJ, rtde_control.PathEntry.PositionJoints, [*target, 1.0, 1.0, 0.0]
        )
    )
    ok(p.control.movePath(path, False), "movePath")
    p.reached_q(target)


def _stream(p: Probe, send: ProbeFn, steps: int) -> None:
    for _ in range(steps):
        start = p.control.initPeriod()
        send(p)
        p.control.waitPeriod(start)


def _servo_j(p: Probe) -> None:
    start, steps = p.q(), round(0.5 * p.rate)
    k = [0]

    def send(p: Probe) -> None:
        k[0] += 1
        s = 0.5 * (1 - math.cos(math.pi * min(k[0], steps) / steps))
        target = [q + s * d for q, d in zip(start, (0.1, 0.0, 0.0, 0.0, 0.0, 0.1), strict=True)]
        ok(p.control.servoJ(target, 0.0, 0.0, 1 / p.rate, 0.1, 300), "servoJ")

    _stream(p, send, 2 * steps)  # the swing, then as long holding its end
    p.control.servoStop(10.0)
    p.reached_q([q + d for q, d in zip(start, (0.1, 0.0, 0.0, 0.0, 0.0, 0.1), strict=True)])


def _servo_l(p: Probe) -> None:
    start, steps = p.pose(), round(0.5 * p.rate)
    k = [0]

    def at(i: int) -> list[float]:
        s = 0.5 * (1 - math.cos(math.pi * min(i, steps) / steps))
        return [start[0], start[1], start[2] + 0.02 * s, *start[3:]]

    def send(p: Probe) -> None:
        k[0] += 1
        ok(p.control.servoL(at(k[0]), 0.0, 0.0, 1 / p.rate, 0.1, 300), "servoL")

    _stream(p, send, 2 * steps)  # the swing, then as long holding its end
    p.control.servoStop(10.0)
    p.reached_pose(at(steps))


def _servo_stop(p: Probe) -> None:
    start = p.q()
    _stream(p, lambda p: ok(p.control.servoJ(start, 0.0, 0.0, 1 / p.rate, 0.1, 300), "servoJ"), 10)
    ok(p.control.servoStop(10.0), "servoStop")
    p.rest()


def _servo_c(p: Probe) -> None:
    target = _up(p, -0.02)
    ok(p.control.servoC(target, 0.05, 0.5, 0.0), "servoC")
    p.reached_pose(target)
    ok(p.control.servoStop(10.0), "servoStop after servoC")


def _moving(p: Probe, joint: int, speed: float) -> bool:
    return wait_until(lambda: abs(p.receiver.getActualQd()[joint] - speed) < 1e-3, 15.0)


def _speed_j(p: Probe) -> None:
    ok(p.control.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, 0.2], 0.5, 0.0), "speedJ")
    assert _moving(p, 5, 0.2), f"joint speeds {list(p.receiver.getActualQd())}"
    ok(p.control.speedStop(10.0), "speedStop")
    p.rest()


def _tcp_speed_z(p: Probe, speed: float) -> bool:
    return wait_until(lambda: abs(p.receiver.getActualTCPSpeed()[2] - speed) < 1e-3, 15.0)


def _speed_l(p: Probe) -> None:
    ok(p.control.speedL([0.0, 0.0, 0.02, 0.0, 0.0, 0.0], 0.25, 0.0), "speedL")
    assert _tcp_speed_z(p, 0.02), f"TCP speed {list(p.receiver.getActualTCPSpeed())}"
    ok(p.control.speedStop(10.0), "speedStop")
    p.rest()


def _stop_j(p: Probe) -> None:
    ok(p.control.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, -0.2], 0.5, 0.0), "speedJ")
    assert _moving(p, 5, -0.2), f"joint speeds {list(p.receiver.getActualQd())}"
    p.control.stopJ(2.0)
    p.rest()


def _stop_l(p: Probe) -> None:
    ok(p.control.speedL([0.0, 0.0, -0.02, 0.0, 0.0, 0.0], 0.25, 0.0), "speedL")
    assert _tcp_speed_z(p, -0.02), f"TCP speed {list(p.receiver.getActualTCPSpeed())}"
    p.control.stopL(1.0)
    p.rest()


def _jog(p: Probe) -> None:
    ok(p.control.jogStart([0.0, 0.0, 0.02, 0.0, 0.0, 0.0]), "jogStart")
    assert _tcp_speed_z(p, 0.02), f"TCP speed {list(p.receiver.getActualTCPSpeed())}"
    ok(p.control.jogStop(), "jogStop")
    p.rest()


def _watchdog(p: Probe) -> None:
    ok(p.control.setWatchdog(0.5), "setWatchdog(0.5 Hz)")
    for _ in range(20):
        ok(p.control.kickWatchdog(), "kickWatchdog")
        time.sleep(0.02)  # the client's pace, not a wait for the fake
    assert p.control.isProgramRunning(), "a kicked watchdog keeps the program running"
    p.script_ended = True  # no more kicks: within 2 s the controller stops the program
    assert wait_until(lambda: not p.control.isProgramRunning(), 20.0), "the unkicked watchdog stopped nothing"


MOTION_PROBES: dict[str, ProbeFn] = {
    "moveJ": _move_j,
    "moveL": _move_l,
    "moveJ_IK": _move_j_ik,
    "moveL_FK": _move_l_fk,
    "movePath": _move_path,
    "servoJ": _servo_j,
    "servoL": _servo_l,
    "servoStop": _servo_stop,
    "speedJ": _speed_j,
    "speedL": _speed_l,
    "speedStop": _speed_j,
    "jogStart": _jog,
    "jogStop": _jog,
    "servoC": _servo_c,
    "stopJ": _stop_j,
    "stopL": _stop_l,
    "setWatchdog": _watchdog,
    "kickWatchdog": _watchdog,
}


# ---- force, modes, contact -----------------------------------------------------------------------------


def _force_mode(p: Probe, stop: bool) -> None:
    z = p.pose()[2]
    ok(p.control.forceModeSetDamping(0.1), "forceModeSetDamping")
    limits = [0.1, 0.1, 0.02, 0.1, 0.1, 0.1]
    ok(
        p.control.forceMode([0.0] * 6, [0, 0, 1, 0, 0, 0], [0.0, 0.0, -10.0, 0.0, 0.0, 0.0], 2, limits),
        "forceMode",
    )
    assert wait_until(lambda: p.pose()[2] < z - 0.002, 15.0), (
        f"force mode pushed nothing down: z {p.pose()[2]}"
    )
    ok(p.control.forceModeStop(), "forceModeStop")
    if stop:
        p.rest()


def _move_until_contact(p: Probe) -> None:
    wall = tcp_pose(p.model, (0.0, -1.57, 1.57, -1.57, -1.57, 0.0))[2] - WALL_BELOW
    ok(p.control.moveUntilContact([0.0, 0.0, -0.02, 0.0, 0.0, 0.0]), "moveUntilContact")
    p.rest()
    assert abs(p.pose()[2] - wall) < 0.005, (
        f"moveUntilContact ended at z {p.pose()[2]}, the wall is at {wall}"
    )


def _contact_detection(p: Probe) -> None:
    ok(p.control.startContactDetection(), "startContactDetection")
    assert p.control.readContactDetection() is False, "no contact at rest in free space"
    assert p.control.stopContactDetection() is False, "stopContactDetection: no contact was detected"


def _freedrive(p: Probe) -> None:
    ok(p.control.freedriveMode(), "freedriveMode")
    assert p.control.getFreedriveStatus() in (0, 1, 2)
    ok(p.control.endFreedriveMode(), "endFreedriveMode")


def _teach(p: Probe) -> None:
    ok(p.control.teachMode(), "teachMode")
    ok(p.control.endTeachMode(), "endTeachMode")


def _protective_stop(p: Probe) -> None:
    ok(p.control.triggerProtectiveStop(), "triggerProtectiveStop")
    assert wait_until(p.receiver.isProtectiveStopped, 10.0), "no protective stop reported"
    p.script_ended = True


MODE_PROBES: dict[str, ProbeFn] = {
    "zeroFtSensor": lambda p: ok(p.control.zeroFtSensor(), "zeroFtSensor"),
    "forceModeSetDamping": lambda p: ok(p.control.forceModeSetDamping(0.05), "forceModeSetDamping"),
    "forceModeSetGainScaling": lambda p: ok(
        p.control.forceModeSetGainScaling(1.0), "forceModeSetGainScaling"
    ),
    "forceMode": lambda p: _force_mode(p, False),
    "forceModeStop": lambda p: _force_mode(p, True),
    "startContactDetection": _contact_detection,
    "readContactDetection": _contact_detection,
    "stopContactDetection": _contact_detection,
    "freedriveMode": _freedrive,
    "endFreedriveMode": _freedrive,
    "teachMode": _teach,
    "endTeachMode": _teach,
    "enableExternalFtSensor": lambda p: ok(p.control.enableExternalFtSensor(False), "enableExternalFtSensor"),
    "ftRtdeInputEnable": lambda p: ok(p.control.ftRtdeInputEnable(False), "ftRtdeInputEnable(False)"),
    "moveUntilContact": _move_until_contact,
    "triggerProtectiveStop": _protective_stop,
}


# ---- the arm's dynamics --------------------------------------------------------------------------------


def _matrix(values: list[float]) -> list[list[float]]:
    """ur_rtde's 36 values are the 6x6 matrix column by column (its script writes m[row, col] to
    register col * 6 + row)."""
    assert len(values) == 36, f"{len(values)} values"
    return [[values[col * 6 + row] for col in range(6)] for row in range(6)]


def _jacobian(p: Probe) -> None:
    q = p.q()
    jac = _matrix(list(p.second(lambda: p.control.getJacobian(q, [0.0] * 6))))
    h = 1e-6
    for j in range(6):
        plus = tcp_pose(p.model, [v + (h if i == j else 0.0) for i, v in enumerate(q)])
        minus = tcp_pose(p.model, [v - (h if i == j else 0.0) for i, v in enumerate(q)])
        linear = [(a - b) / (2 * h) for a, b in zip(plus[:3], minus[:3], strict=True)]
        assert near([jac[r][j] for r in range(3)], linear, 1e-4), f"column {j}: {jac}, numeric {linear}"
        assert abs(math.hypot(*(jac[r][j] for r in range(3, 6))) - 1) < 1e-6, "a revolute joint's axis"


def _mass_matrix(p: Probe) -> None:
    q = p.q()
    m = _matrix(list(p.second(lambda: p.control.getMassMatrix(q, False))))
    assert all(abs(m[i][j] - m[j][i]) < 1e-9 for i in range(6) for j in range(6)), f"not symmetric: {m}"
    low = [[0.0] * 6 for _ in range(6)]  # Cholesky: succeeds only on a positive definite matrix
    for i in range(6):
        for j in range(i + 1):
            s = m[i][j] - sum(low[i][k] * low[j][k] for k in range(j))
            if i == j:
                assert s > 0, f"not positive definite: {m}"
                low[i][i] = math.sqrt(s)
            else:
                low[i][j] = s / low[j][j]
    reference = Reference(p.model).mass_matrix(q)  # an independent Newton-Euler
    off = max(abs(m[i][j] - reference[i][j]) for i in range(6) for j in range(6))
    assert off < 1e-9, f"{off} from Newton-Euler's: {m}"


def _at_rest(p: Probe, call: str, values: list[float]) -> None:
    """ur_rtde 1.6.5's script calls ``get_coriolis_and_centrifugal_torques()`` and
    ``get_jacobian_time_derivative()`` without arguments (so do its mass matrix and Jacobian commands):
    the answer is for the arm's own joints and speeds, whatever the caller passes, on a controller as on
    the fake. At rest the model's answer is zero."""
    ok(near(values, [0.0] * len(values), 1e-12), f"{call} zero at rest: {values}")


def _direct_torque(p: Probe) -> None:
    """Zero torque holds the arm (the controller compensates gravity); its joints exert the gravity
    torques, which rtde_receive reads as the target moments."""
    start = p.q()
    for _ in range(10):
        begin = p.control.initPeriod()
        ok(p.control.directTorque([0.0] * 6), "directTorque")
        p.control.waitPeriod(begin)
    moments = list(p.receiver.getTargetMoment())
    hold = list(Reference(p.model).rnea(p.q(), [0.0] * 6, [0.0] * 6, GRAVITY))
    p.control.speedStop(10.0)
    assert near(p.q(), start, 1e-9), f"moved: {p.q()} from {start}"
    assert near(moments, hold, 1e-6), f"target moments {moments}, gravity torques {hold}"


def _external_wrench(p: Probe) -> None:
    ok(p.control.ftRtdeInputEnable(True), "ftRtdeInputEnable(True)")
    ok(p.control.setExternalForceTorque([0.0, 0.0, 5.0, 0.0, 0.0, 0.0]), "setExternalForceTorque")
    assert wait_until(lambda: abs(p.receiver.getActualTCPForce()[2] - 5.0) < 0.5, 10.0), (
        f"TCP force {list(p.receiver.getActualTCPForce())}"
    )


DYNAMICS_PROBES: dict[str, ProbeFn] = {
    "getJacobian": _jacobian,
    "getJacobianTimeDerivative": lambda p: _at_rest(
        p,
        "getJacobianTimeDerivative",
        list(p.second(lambda: p.control.getJacobianTimeDerivative(p.q(), [0.0] * 6, [0.0] * 6))),
    ),
    "getMassMatrix": _mass_matrix,
    "getCoriolisAndCentrifugalTorques": lambda p: _at_rest(
        p,
        "getCoriolisAndCentrifugalTorques",
        list(p.second(lambda: p.control.getCoriolisAndCentrifugalTorques(p.q(), [0.0] * 6))),
    ),
    "directTorque": _direct_torque,
    "setExternalForceTorque": _external_wrench,
}


# ---- ur_rtde's script itself ---------------------------------------------------------------------------


def _said(p: Probe, text: str) -> bool:
    return p.primary.wait_for(lambda: any(text in t for t in p.primary.texts()), 15.0)


def _custom_function(p: Probe) -> None:
    ok(p.control.sendCustomScriptFunction("probe_function", 'textmsg("from probe_function")\n'), "sent")
    assert _said(p, "from probe_function"), p.primary.describe()


DONE = "  write_output_integer_register(0, 2)\n"
"""ur_rtde waits for a custom script to say it is done as its own script does (register 0 = 2)."""


def _custom_script(p: Probe) -> None:
    ok(
        p.control.sendCustomScript('def probe_script():\n  textmsg("from probe_script")\n' + DONE + "end\n"),
        "sent",
    )
    assert _said(p, "from probe_script"), p.primary.describe()


def _custom_file(p: Probe) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "probe.script"
        path.write_text(
            'def probe_file():\n  textmsg("from probe_file")\n' + DONE + "end\n", encoding="ascii"
        )
        ok(p.control.sendCustomScriptFile(str(path)), "sendCustomScriptFile")
    assert _said(p, "from probe_file"), p.primary.describe()


def _reupload(p: Probe) -> None:
    ok(p.control.reuploadScript(), "reuploadScript")
    assert wait_until(p.control.isProgramRunning, 10.0)


def _custom_control_file(p: Probe) -> None:
    p.control.setCustomScriptFile("")  # "" goes back to ur_rtde's own script: effective at the upload
    _reupload(p)


def _stop_script(p: Probe) -> None:
    p.script_ended = True
    p.control.stopScript()
    assert wait_until(lambda: p.receiver.getRuntimeState() != 2, 10.0), "the script still runs"


def _disconnect(p: Probe) -> None:
    p.script_ended = True
    p.control.disconnect()
    assert p.control.isConnected() is False


def _reconnect(p: Probe) -> None:
    p.control.disconnect()
    ok(p.control.reconnect(), "reconnect")
    assert p.control.isConnected()
    assert wait_until(p.control.isProgramRunning, 10.0)


LIFE_PROBES: dict[str, ProbeFn] = {
    "sendCustomScriptFunction": _custom_function,
    "sendCustomScript": _custom_script,
    "sendCustomScriptFile": _custom_file,
    "reuploadScript": _reupload,
    "setCustomScriptFile": _custom_control_file,
    "reconnect": _reconnect,
    "stopScript": _stop_script,
    "disconnect": _disconnect,
}
