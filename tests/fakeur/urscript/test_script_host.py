"""ScriptHost: what the controller hands each program run."""

from __future__ import annotations

import socket

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import lib_sockets
from urdaemon.fakeur.urscript.script_host import InputRegisters, ScriptHost

DT = 0.002


def _arm() -> FakeArm:
    model = load_ur_model("ur5e")
    return FakeArm(model, model.dh)


def test_now_is_the_arms_clock_and_defaults_are_fresh() -> None:
    arm = _arm()
    host = ScriptHost(arm, step_time=DT)
    arm.step(DT)
    assert host.now == arm.timestamp == DT
    assert host.input_registers == InputRegisters()
    assert host.watchdogs == {}
    assert (host.sockets, host.motion, host.config, host.thread) == (None, None, None, 0)
    other = ScriptHost(arm, step_time=DT)
    assert other.input_registers is not host.input_registers


def test_input_registers_are_shared_when_the_controller_passes_them() -> None:
    registers = InputRegisters()
    arm = _arm()
    first = ScriptHost(arm, step_time=DT, input_registers=registers)
    second = ScriptHost(arm, step_time=DT, input_registers=registers)
    registers.ints[3] = 9
    assert first.input_registers.ints[3] == second.input_registers.ints[3] == 9


def test_close_closes_the_programs_sockets() -> None:
    """The controller ends a program (stop, a new program, an error): its peers see the connection end."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        listener.settimeout(5.0)
        host = ScriptHost(_arm(), step_time=DT)
        call = lib_sockets.socket_open(host, "127.0.0.1", listener.getsockname()[1], "socket_0")
        opened = None
        for _ in range(100):
            try:
                next(call)
            except StopIteration as stop:
                opened = stop.value
                break
            host.arm.step(DT)
        assert opened is True
        peer, _ = listener.accept()
        peer.settimeout(5.0)
        with peer:
            host.close()
            assert peer.recv(8) == b""
    assert host.sockets.get("socket_0") is None
    host.close()
