"""Real programs run in the interpreter, with stub controller builtins: our control script (servoj
streaming, mode switches, STOPPED) and ur_rtde's rtde_control script (a command through the registers)."""

from __future__ import annotations

from collections.abc import Generator, Iterator
from pathlib import Path
from typing import Any, cast

import pytest

from tests.fakeur.urscript.test_compiler import RTDE_CONTROL_SCRIPT, control_script
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.lib_core import floor, get_steptime, norm, popup, str_cat, sync, textmsg
from urdaemon.fakeur.urscript.runtime import Builtin, ScriptRun, UrList
from urdaemon.protocols.primary import headless_program

MULT = 1_000_000
REVERSE_INTS = 8
MODE_STOPPED, MODE_IDLE, MODE_SERVOJ = -2, 0, 1


class Controller:
    """A stand-in for the fake controller: a host and the stub builtins our scripts need."""

    def __init__(self) -> None:
        self.step_time = 0.002
        self.thread = 0
        self.cycle = 0
        self.messages: list[str] = []
        self.frames: list[UrList] = []
        self.servo_targets: list[tuple[int, list[float]]] = []
        self.stops = 0
        self.q = [0.1 + 0.01 * j for j in range(6)]
        self.inputs: dict[int, int] = {}
        self.outputs: dict[int, int] = {}
        self._read_in = -1

    def message(self, kind: str, text: str) -> None:
        self.messages.append(text)

    def builtins(self) -> dict[str, Builtin]:
        table: dict[str, Builtin] = {
            f.__name__: Builtin(f.__name__, f, False)
            for f in (floor, get_steptime, norm, popup, str_cat, textmsg)
        }
        table["sync"] = Builtin("sync", sync, True)
        stubs: dict[str, tuple[Any, bool]] = {
            "socket_open": (lambda host, address, port, name: True, False),
            "socket_close": (lambda host, name: None, False),
            "socket_send_int": (lambda host, value, name: None, False),
            "socket_read_binary_integer": (self._read, True),
            "servoj": (self._servoj, True),
            "stopj": (self._stopj, False),
            "get_joint_positions": (lambda host: UrList(self.q), False),
            "get_target_joint_speeds": (lambda host: UrList([0.0] * 6), False),
            "read_input_integer_register": (lambda host, n: self.inputs.get(n, 0), False),
            "write_output_integer_register": (
                lambda host, n, value: self.outputs.__setitem__(n, value),
                False,
            ),
            "force_mode_set_gain_scaling": (lambda host, scaling: None, False),
            "force_mode_set_damping": (lambda host, damping: None, False),
            "is_steady": (lambda host: True, False),
        }
        table.update({name: Builtin(name, f, blocking) for name, (f, blocking) in stubs.items()})
        return table

    def _read(self, host: Any, number: int, name: str, timeout: float) -> Generator[None, None, UrList]:
        """The reverse socket delivers one queued frame per cycle; the other sockets stay silent."""
        if name != "reverse_socket":
            while True:
                yield
        while self._read_in == self.cycle or not self.frames:
            yield
        self._read_in = self.cycle
        return self.frames.pop(0)

    def _servoj(self, host: Any, q: list[float], *rest: float) -> Iterator[None]:
        self.servo_targets.append((self.cycle, list(q)))
        self.q = list(q)
        yield

    def _stopj(self, host: Any, a: float) -> None:
        self.stops += 1

    def step(self, run: ScriptRun, count: int = 1) -> None:
        for _ in range(count):
            run.step()
            self.cycle += 1


def reverse_frame(mode: int, q: list[float] | None = None, keepalive_ms: int = 100) -> UrList:
    fields = [round(x * MULT) for x in (q or [0.0] * 6)]
    return UrList([REVERSE_INTS, keepalive_ms, *fields, mode])


@pytest.mark.parametrize("wrapped", [False, True], ids=["unwrapped", "headless"])
def test_our_control_script_streams_servoj_and_ends_on_stopped(wrapped: bool) -> None:
    text = control_script(tool_setup=())
    if wrapped:
        text = headless_program(text).split("\n", 1)[1]
    controller = Controller()
    program = compile_program(text, series="e", version=(5, 15), builtins=controller.builtins())
    run = program.start(cast(Any, controller))
    controller.step(run, 3)
    assert any("control active" in m for m in controller.messages)
    targets = [[0.1 + 0.001 * i + 0.01 * j for j in range(6)] for i in range(5)]
    controller.frames = [reverse_frame(MODE_SERVOJ, q) for q in targets]
    controller.step(run, 8)
    assert run.error is None
    streamed = [q for _, q in controller.servo_targets]
    assert len(streamed) >= len(targets)
    for target in targets:
        assert any(all(abs(a - b) < 1e-9 for a, b in zip(q, target, strict=True)) for q in streamed)
    cycles_with_servoj = [cycle for cycle, _ in controller.servo_targets]
    assert len(set(cycles_with_servoj)) == len(cycles_with_servoj)  # one servoj per cycle
    controller.frames = [reverse_frame(MODE_STOPPED)]
    controller.step(run, 4)
    assert run.done
    assert run.error is None
    assert any("STOPPED received" in m for m in controller.messages)
    assert controller.stops >= 1


def test_our_control_script_aborts_when_the_reverse_socket_times_out() -> None:
    controller = Controller()
    text = control_script(tool_setup=())
    run = compile_program(text, series="e", version=(5, 15), builtins=controller.builtins()).start(
        cast(Any, controller)
    )
    controller.frames = [reverse_frame(MODE_IDLE), UrList([0])]
    controller.step(run, 5)
    assert run.done
    assert run.error is None
    assert any("Socket timed out" in m for m in controller.messages)


@pytest.mark.skipif(
    not RTDE_CONTROL_SCRIPT.exists(), reason="ur_rtde's captured script is not on this machine"
)
def test_ur_rtde_control_script_answers_a_command_and_stops() -> None:
    controller = Controller()
    text = Path(RTDE_CONTROL_SCRIPT).read_text(encoding="ascii")
    run = compile_program(text, series="e", version=(5, 15), builtins=controller.builtins()).start(
        cast(Any, controller)
    )
    controller.step(run, 3)
    assert run.error is None
    assert controller.outputs[0] == 1  # signal_ready
    controller.inputs[0] = 47  # is_steady
    controller.step(run, 2)
    assert run.error is None
    assert controller.outputs[1] == 1
    assert controller.outputs[0] == 2  # done with the command
    controller.inputs[0] = 0
    controller.step(run, 2)
    assert controller.outputs[0] == 1
    controller.inputs[0] = 255  # stop script
    controller.step(run, 3)
    assert run.done
    assert run.error is None
    assert "RTDE Control Script Terminated" in controller.messages
