"""Judge: every method of SDU's ur_rtde ``RTDEControlInterface`` against the fake, held to the table in
docs/fake-robot.md (``## What independent clients can call``).

Each method has a probe (ur_rtde_probes.py, ur_rtde_motion_probes.py): a sane call near the fake's home
and a check of its effect, read back through ``rtde_receive`` and our own kinematics. A call works when
its probe passes, the fake's primary interface reported no runtime error meanwhile, and ur_rtde's script
still runs (unless the probe stopped it on purpose). The test fails when a method exists that the table
does not list (a new ur_rtde adds one), when a "works" row does not work, and when a "refused" or
"fails" row now works (flip it to "works": one word).

The probes run in groups, one fake process and one ``RTDEControlInterface`` per group; a call that
leaves the interface or its script broken is followed by a fresh interface.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator
from typing import Any

import pytest

from tests.fakeur.client_table import read_table
from tests.fakeur.judges import PrimaryWatch, fake_robot, tcp_pose, wait_until
from tests.fakeur.ur_rtde_motion_probes import (
    DYNAMICS_PROBES,
    LIFE_PROBES,
    MODE_PROBES,
    MOTION_PROBES,
    WALL_BELOW,
)
from tests.fakeur.ur_rtde_probes import HOME, QUERY_PROBES, Probe, ProbeFn

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = pytest.mark.timeout(300)

CLIENT = "ur_rtde RTDEControlInterface"
MODEL = "ur10e"
VERSION = "5.26.0"
"""A controller new enough for every call ur_rtde 1.6.5 has (its script drops the lines of builtins
newer than the controller: Jacobian and dynamics since 5.23, direct_torque since 5.26)."""
RATE = 500.0
STOPPED = 1
"""RTDE's runtime_state of a controller running no program."""

GROUPS: dict[str, dict[str, ProbeFn]] = {
    "queries": QUERY_PROBES,
    "motion": MOTION_PROBES,
    "modes": MODE_PROBES,
    "dynamics": DYNAMICS_PROBES,
    "life": LIFE_PROBES,
}


def _methods() -> set[str]:
    """The public methods of ur_rtde's RTDEControlInterface (not its flag and feature constants)."""
    cls = rtde_control.RTDEControlInterface
    return {
        name
        for name in dir(cls)
        if not name.startswith("_")
        and callable(getattr(cls, name))
        and not isinstance(getattr(cls, name), type)
    }


def test_the_table_lists_every_method_and_a_probe_tries_each() -> None:
    table = read_table(CLIENT)
    methods = _methods()
    probed = {name for probes in GROUPS.values() for name in probes}
    assert not methods - table.keys(), (
        f"ur_rtde methods the table does not list: {sorted(methods - table.keys())}"
    )
    assert not table.keys() - methods, f"the table lists what ur_rtde lacks: {sorted(table.keys() - methods)}"
    assert probed == methods, (
        f"no probe: {sorted(methods - probed)}; not a method: {sorted(probed - methods)}"
    )


def _dashboard_stop(address: str) -> None:
    """Stop whatever program runs, as an operator would, through the dashboard (not ur_rtde)."""
    with socket.create_connection((address, 29999), timeout=10) as sock:
        sock.settimeout(10)
        sock.recv(4096)  # the greeting
        sock.sendall(b"stop\n")
        sock.recv(4096)


def _fresh_control(probe: Probe) -> None:
    """A new RTDEControlInterface after a call that left the old one or its script broken."""
    with contextlib.suppress(Exception):
        probe.control.disconnect()
    if probe.receiver.getRuntimeState() != STOPPED:
        _dashboard_stop(probe.fake.address)
    wait_until(lambda: probe.receiver.getRuntimeState() == STOPPED, 10.0)
    if probe.receiver.isProtectiveStopped():
        return  # the group's last probe; nothing runs after it
    probe.control = probe.make_control()
    probe.tcp = [0.0] * 6


def _try(probe: Probe, name: str, run: ProbeFn) -> str:
    """ "" when the call works, else what went wrong."""
    seen = len(probe.primary.messages)
    probe.script_ended = False
    try:
        run(probe)
        problem = ""
    except Exception as err:  # what ur_rtde raises, or the probe's check
        problem = f"{type(err).__name__}: {err}"
    probe.settle()
    errors = [m for m in probe.primary.messages[seen:] if type(m).__name__ == "RuntimeExceptionMessage"]
    if errors:
        problem += f" runtime error: {errors[0].text} (line {errors[0].line})"
    running = probe.control.isConnected() and probe.control.isProgramRunning()
    if not running and not probe.script_ended:
        problem += " ur_rtde's script stopped"
    if problem or not running:
        _fresh_control(probe)
    return problem.strip()


@contextlib.contextmanager
def _probe_on_a_fake(group: str) -> Iterator[Probe]:
    flags = ["--powered", "--controller-version", VERSION]
    if group == "modes":
        x, y, z = tcp_pose(MODEL, HOME)[:3]
        flags.append(f"--wall={x},{y},{z - WALL_BELOW},0,0,1")  # "=": x is negative
    with fake_robot(MODEL, *flags) as fake:
        primary = PrimaryWatch(fake.address)
        receiver = rtde_receive.RTDEReceiveInterface(fake.address, RATE)

        def make_control() -> Any:
            return rtde_control.RTDEControlInterface(fake.address)

        probe = Probe(fake, primary, receiver, make_control(), RATE, make_control)
        try:
            yield probe
        finally:
            with contextlib.suppress(Exception):
                probe.control.stopScript()
                probe.control.disconnect()
            receiver.disconnect()
            primary.close()


@pytest.mark.parametrize("group", GROUPS)
def test_each_call_does_what_the_table_says(group: str) -> None:
    table = read_table(CLIENT)
    wrong: list[str] = []
    with _probe_on_a_fake(group) as probe:
        for name, run in GROUPS[group].items():
            problem = _try(probe, name, run)
            if table[name] == "works" and problem:
                wrong.append(f"{name}: the table says works, but {problem}")
            elif table[name] != "works" and not problem:
                wrong.append(f"{name}: the table says {table[name]}, but it works now: flip the row")
        tail = probe.fake.log_tail()
    assert not wrong, "\n".join(wrong) + f"\nfake log:\n{tail}"
