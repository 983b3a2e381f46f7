"""The doctor's checks from tables: facts in, each check's verdict out (doctor/checks.py is pure)."""

from __future__ import annotations

from typing import Any

import pytest

from urdaemon.doctor.checks import Check, Verdict, host_checks, robot_checks, worst

OK, WARN, FAIL, UNKNOWN, NA = Verdict.OK, Verdict.WARN, Verdict.FAIL, Verdict.UNKNOWN, Verdict.NA

HOST: dict[str, Any] = {
    "release": "6.8.0-rt8",
    "version": "#1 SMP PREEMPT_RT",
    "preempt_rt": True,
    "rtprio_limit": 0,
    "cap_sys_nice": False,
    "root": False,
    "loop_policy": "SCHED_FIFO",
    "loop_priority": 80,
    "realtime_priority": 80,
    "realtime_error": None,
}


def _host(**changes: Any) -> dict[str, Any]:
    return {**HOST, **changes}


HOST_TABLE: list[tuple[str, dict[str, Any], dict[str, Verdict], str]] = [
    ("all well", _host(), {"kernel": OK, "realtime_priority": OK}, ""),
    (
        "no PREEMPT_RT",
        _host(preempt_rt=False, version="#1 SMP PREEMPT_DYNAMIC"),
        {"kernel": WARN, "realtime_priority": OK},
        "PREEMPT_RT absent: cycles may be late under load",
    ),
    (
        "asked but refused",
        _host(loop_policy="SCHED_OTHER", loop_priority=0, realtime_error="Operation not permitted"),
        {"kernel": OK, "realtime_priority": FAIL},
        "rtprio limit of at least 80",
    ),
    (
        "not asked, permitted by rtprio",
        _host(realtime_priority=0, loop_policy="SCHED_OTHER", loop_priority=0, rtprio_limit=95),
        {"kernel": OK, "realtime_priority": WARN},
        "set realtime_priority (e.g. 80)",
    ),
    (
        "not asked, permitted as root",
        _host(realtime_priority=0, loop_policy="SCHED_OTHER", root=True),
        {"kernel": OK, "realtime_priority": WARN},
        "set realtime_priority (e.g. 80)",
    ),
    (
        "not asked, not permitted",
        _host(realtime_priority=0, loop_policy="SCHED_OTHER"),
        {"kernel": OK, "realtime_priority": WARN},
        "allow SCHED_FIFO",
    ),
]


@pytest.mark.parametrize(("case", "host", "verdicts", "action"), HOST_TABLE, ids=[c[0] for c in HOST_TABLE])
def test_host_checks(case: str, host: dict[str, Any], verdicts: dict[str, Verdict], action: str) -> None:
    checks = host_checks(host)
    assert {c.name: c.verdict for c in checks} == verdicts
    actions = " ".join(c.action for c in checks)
    assert action in actions
    for check in checks:
        assert (check.action == "") == (check.verdict is OK), check


CONTROLLER: dict[str, Any] = {
    "address": "10.0.0.20",
    "headless": True,
    "read_only": False,
    "links": {"rtde": True, "primary": True, "error": ""},
    "rtde_version": [5, 15, 0, 0],
    "polyscope_version": [5, 15, 0, 0],
    "remote_control": True,
    "remote_control_text": "true",
    "dashboard": {"connected": True, "error": None, "round_trips_ms": [1.0] * 19 + [3.0]},
    "callbacks": {
        "listening_on": "10.0.0.1",
        "dials": "10.0.0.1",
        "ports": {
            name: {"port": port, "listening": True, "connected": True, "peer": "10.0.0.20"}
            for name, port in (("reverse", 50001), ("script_sender", 50002), ("trajectory", 50003))
        },
    },
    "clock": {
        "samples": 200,
        "period_ms": 2.0,
        "offset_s": 1.7e9,
        "jitter_ms": 0.2,
        "baseline_s": 60.0,
        "drift_ppm": 3.0,
        "drift_bound_ppm": 3.3,
    },
}
ROBOT: dict[str, Any] = {
    "backend": "ur",
    "rate_hz": 500.0,
    "cycles": 100_000,
    "missed_cycles": 0,
    "late_cycles": 0,
    "turnaround": {"count": 100_000, "p50_us": 80.0, "p99_us": 200.0, "p999_us": 300.0, "max_us": 900.0},
    "controller": CONTROLLER,
}
ALL_OK = dict.fromkeys(
    (
        "dashboard",
        "primary",
        "round_trip",
        "controller_version",
        "remote_control",
        "callback_ports",
        "rtde_jitter",
        "clock_offset",
        "cycles",
        "turnaround",
    ),
    OK,
)


def _robot(controller: dict[str, Any] | None = None, **changes: Any) -> dict[str, Any]:
    return {**ROBOT, "controller": {**CONTROLLER, **(controller or {})}, **changes}


def _ports(**changes: Any) -> dict[str, Any]:
    ports = {name: {**entry, **changes} for name, entry in CONTROLLER["callbacks"]["ports"].items()}
    return {**CONTROLLER["callbacks"], "ports": ports}


NO_DASHBOARD = {"connected": False, "error": "dashboard: connection refused", "round_trips_ms": []}
ROBOT_TABLE: list[tuple[str, dict[str, Any], dict[str, Verdict], str]] = [
    ("all well", _robot(), {}, ""),
    (
        "dashboard disabled",
        _robot({"dashboard": NO_DASHBOARD, "polyscope_version": None, "remote_control": None}),
        {"dashboard": FAIL, "round_trip": UNKNOWN, "remote_control": UNKNOWN},
        "Settings > Security > Services",
    ),
    (
        "primary down",
        _robot({"links": {"rtde": True, "primary": False, "error": "primary: connection lost"}}),
        {"primary": FAIL},
        "Settings > Security > Services",
    ),
    (
        "slow dashboard",
        _robot({"dashboard": {**CONTROLLER["dashboard"], "round_trips_ms": [12.0] * 20}}),
        {"round_trip": WARN},
        "wired link",
    ),
    (
        "one very slow reply",
        _robot({"dashboard": {**CONTROLLER["dashboard"], "round_trips_ms": [1.0] * 19 + [80.0]}}),
        {"round_trip": WARN},
        "wired link",
    ),
    (
        "remote control off, headless",
        _robot({"remote_control": False, "remote_control_text": "false"}),
        {"remote_control": FAIL},
        "remote control is off: set the robot to Remote Control on the pendant",
    ),
    (
        "remote control off, URCap",
        _robot({"remote_control": False, "headless": False}),
        {"remote_control": WARN},
        "Settings > System > Remote Control",
    ),
    (
        "CB3",
        _robot({"polyscope_version": [3, 15, 8, 0], "rtde_version": [3, 15, 8, 0], "remote_control": None}),
        {"remote_control": NA},
        "",
    ),
    (
        "e-Series before 5.6: no remote control query",
        _robot({"polyscope_version": [5, 4, 0, 0], "rtde_version": [5, 4, 0, 0], "remote_control": None}),
        {"remote_control": UNKNOWN, "controller_version": WARN},
        "5.10 or later",
    ),
    (
        "versions disagree",
        _robot({"polyscope_version": [5, 15, 0, 0], "rtde_version": [5, 11, 0, 0]}),
        {"controller_version": WARN},
        "two different controllers",
    ),
    (
        "no version at all",
        _robot({"polyscope_version": None, "rtde_version": None}),
        {"controller_version": UNKNOWN},
        "",
    ),
    (
        "program not connected",
        _robot({"callbacks": _ports(connected=False, peer=None)}),
        {"callback_ports": WARN},
        "firewall",
    ),
    (
        "ports not open",
        _robot({"callbacks": {**_ports(listening=False), "listening_on": None}}),
        {"callback_ports": FAIL},
        "daemon's log",
    ),
    ("read-only", _robot({"read_only": True, "callbacks": {}}), {"callback_ports": NA}, ""),
    (
        "bunched packages",
        _robot({"clock": {**CONTROLLER["clock"], "jitter_ms": 4.5}}),
        {"rtde_jitter": WARN},
        "packages arrive bunched",
    ),
    (
        "no RTDE",
        _robot({"clock": {"samples": 0, "offset_s": None}}),
        {"rtde_jitter": UNKNOWN, "clock_offset": UNKNOWN},
        "",
    ),
    (
        "one package: the stream stands still",
        _robot({"clock": {"samples": 1, "offset_s": None}}),
        {"rtde_jitter": UNKNOWN, "clock_offset": UNKNOWN},
        "",
    ),
    (
        "clocks drift apart",
        _robot({"clock": {**CONTROLLER["clock"], "drift_ppm": -400.0, "drift_bound_ppm": 5.0}}),
        {"clock_offset": WARN},
        "NTP",
    ),
    (
        "a drift within its bound is not judged a drift",
        _robot({"clock": {**CONTROLLER["clock"], "drift_ppm": 150.0, "drift_bound_ppm": 100.0}}),
        {},
        "",
    ),
    (
        "baseline too short",
        _robot({"clock": {**CONTROLLER["clock"], "baseline_s": 2.0, "drift_ppm": 900.0}}),
        {},
        "",
    ),
    ("a few late cycles", _robot(late_cycles=50), {}, ""),
    ("late cycles", _robot(late_cycles=500), {"cycles": WARN}, "realtime_priority"),
    ("many missed cycles", _robot(missed_cycles=5000), {"cycles": FAIL}, "realtime_priority"),
    # a mock's missed cycles lose nothing physical: judged by its own limit (25 %; 2.5 % warns)
    ("a mock's 2 % lagged", _robot(missed_cycles=2000, lag_fraction=0.25), {}, ""),
    ("a mock's 5 % lagged", _robot(missed_cycles=5000, lag_fraction=0.25), {"cycles": WARN}, ""),
    ("a mock's 30 % lagged", _robot(missed_cycles=45_000, lag_fraction=0.25), {"cycles": FAIL}, ""),
    ("no cycles yet", _robot(cycles=0), {"cycles": UNKNOWN}, ""),
    (
        "slow turnaround",
        _robot(turnaround={"count": 10, "p50_us": 400.0, "p99_us": 800.0, "max_us": 1000.0}),
        {"turnaround": WARN},
        "realtime_priority",
    ),
    (
        "turnaround over a period",
        _robot(turnaround={"count": 10, "p50_us": 2500.0, "p99_us": 3000.0, "max_us": 4000.0}),
        {"turnaround": FAIL},
        "period 2000 us",
    ),
    ("no command yet", _robot(turnaround={"count": 0}), {"turnaround": UNKNOWN}, ""),
]


@pytest.mark.parametrize(("case", "robot", "changed", "action"), ROBOT_TABLE, ids=[c[0] for c in ROBOT_TABLE])
def test_robot_checks(case: str, robot: dict[str, Any], changed: dict[str, Verdict], action: str) -> None:
    checks = robot_checks(robot)
    assert {c.name: c.verdict for c in checks} == {**ALL_OK, **changed}
    assert action in " ".join(c.action for c in checks)
    for check in checks:
        assert check.measured, check
        assert (check.action == "") == (check.verdict in (OK, NA, UNKNOWN)), check


@pytest.mark.parametrize("kind", ["mock", "servo"])
def test_a_robot_without_a_controller_says_so(kind: str) -> None:
    robot = {**ROBOT, "backend": kind, "controller": None, "why": f"{kind} backend: no controller"}
    robot["turnaround"] = {"count": 0}
    checks = robot_checks(robot)
    assert [(c.name, c.verdict) for c in checks] == [("controller", NA), ("cycles", OK), ("turnaround", NA)]
    assert checks[0].measured == f"{kind} backend: no controller"


def test_the_round_trip_reports_min_median_max_and_std() -> None:
    check = robot_checks(_robot({"dashboard": {"connected": True, "round_trips_ms": [1.0, 2.0, 3.0]}}))[2]
    assert check.name == "round_trip"
    assert check.measured == "dashboard robotmode x3: min 1.00 / median 2.00 / max 3.00 ms, std 0.82 ms"


@pytest.mark.parametrize(
    ("verdicts", "expected"),
    [
        ((), OK),
        ((OK, NA), OK),
        ((OK, UNKNOWN), UNKNOWN),
        ((WARN, UNKNOWN, OK), WARN),
        ((OK, FAIL, WARN), FAIL),
    ],
)
def test_worst(verdicts: tuple[Verdict, ...], expected: Verdict) -> None:
    assert worst([Check(str(i), v, "m") for i, v in enumerate(verdicts)]) is expected
