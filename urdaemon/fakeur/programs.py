"""The programs a fake controller runs: compiled, started, stepped each cycle, and ended.

Scripts arrive on the primary, secondary and real-time interfaces (or from ``play``) and are compiled
as a controller compiles them before they run. Compiling (parsing) takes tens of milliseconds the
first time a text is seen, so it runs in a worker thread, never on the event loop where every fake's
clock ticks; what arrived is still handled strictly in its order of arrival (a ``def``, then a bare
line, then a ``sec`` program start in that order), controller commands included. A ``def`` program
or bare lines replace the running program, a ``sec`` program runs beside it. Every cycle the main
program is stepped while it plays and while it is pausing (its motion slows to rest along its path),
then every ``sec`` program; its RTDE watchdogs are checked while it plays. A compile or runtime error
is a RUNTIME_EXCEPTION message naming line and column; a program that does not compile never starts.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import math
import sys
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from urdaemon.errors import ProtocolError, UrDaemonError
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urp import UrpProgram
from urdaemon.fakeur.urscript.lib_io import apply_runstate_outputs
from urdaemon.fakeur.urscript.script_host import InputRegisters, ScriptHost
from urdaemon.protocols import primary as prim
from urdaemon.protocols import script_sender
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import RuntimeState
from urdaemon.shell import Shell, connect

__all__ = ["MAX_PENDING_SCRIPTS", "Programs", "RunningScript"]

log = logging.getLogger("urdaemon.fakeur")

MAX_PENDING_SCRIPTS = 64
"""Scripts waiting to be compiled before a script port stops reading its client (TCP flow control)."""
URCAP_TIMEOUT_S = 5.0
"""How long the External Control program waits to connect to the daemon and for the first line."""
URCAP_MORE_S = 0.2
"""The URCap keeps reading lines only while more arrive this soon (docs/protocols.md §4.3)."""

_COMPILER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="urscript-compile")
"""One thread compiles for every fake of the process: parsing is pure Python and holds the GIL, so
with several compiling threads the event loop (and every fake's clock) would wait its turn behind
each of them; with one it gets the GIL back at every switch interval (5 ms)."""


@dataclass
class RunningScript:
    """A program the interpreter runs: its name, its run (``ScriptRun``) and the host its builtins use."""

    name: str
    run: Any
    host: ScriptHost
    failure: str | None = None
    """Why the interpreter itself failed while running it (a bug there, not the program's error)."""


@dataclass(frozen=True, slots=True)
class _Arrival:
    name: str
    text: str
    number: int
    """Its place among the scripts that arrived (1, 2, ...)."""


@dataclass(frozen=True, slots=True)
class _Action:
    action: Callable[[], None]
    after: int
    """How many scripts had arrived before this command."""


class Programs:
    """The main program and the ``sec`` programs of one controller, and the scripts waiting to start."""

    def __init__(
        self,
        arm: FakeArm,
        *,
        controller_version: tuple[int, int, int, int],
        step_time: float,
        address: str,
        input_registers: InputRegisters,
        broadcast: Callable[[Any], None],
    ) -> None:
        self.arm = arm
        major, minor = controller_version[:2]
        self.series = "e" if major >= 5 else "cb3"
        self.version = (major, minor)
        self.step_time = step_time
        self.address = address
        self.input_registers = input_registers
        self.broadcast = broadcast
        """Sends a robot message to every primary client."""
        self.main: RunningScript | None = None
        self.secondary: list[RunningScript] = []
        self.name: str | None = None
        """The name of the last main program started."""
        self.input_times: dict[str, float] = {}
        """Controller time each RTDE input variable last arrived (what the watchdogs check)."""
        self.compiles = 0
        """Scripts compiled (in the worker thread) so far."""
        self.loaded_urp: tuple[str, UrpProgram] | None = None
        """The ``.urp`` program ``load`` read last: its path and translation (what ``play`` runs, as
        PolyScope plays the program it loaded, not the file as it is now)."""
        self._pending: deque[_Arrival | _Action] = deque()
        self._arrived = 0
        self._dropped_through = 0
        """Scripts up to this arrival number are not started: a stop came after them."""
        self._acting_after: int | None = None
        """While a queued command runs: how many scripts had arrived when it did."""
        self._room = asyncio.Event()
        self._room.set()
        self._idle = asyncio.Event()
        self._idle.set()
        self._worker: asyncio.Task[None] | None = None

    # ---- arrivals, in order ------------------------------------------------------------------------

    def submit(self, name: str, text: str) -> None:
        """Compile ``text`` off the event loop, then start it, after everything that arrived before."""
        self._arrived += 1
        self._enqueue(_Arrival(name, text, self._arrived))

    def then(self, action: Callable[[], None]) -> None:
        """Do ``action`` (a controller command) now, or after the scripts still waiting to start."""
        if not self._pending:
            action()
            return
        self._enqueue(_Action(action, self._arrived))

    @property
    def busy(self) -> bool:
        """Whether scripts are waiting to be compiled or started."""
        return bool(self._pending)

    async def settled(self) -> None:
        """Wait until every script that arrived has been compiled and started (or refused)."""
        await self._idle.wait()

    async def room(self) -> None:
        """Wait while too many scripts are waiting: the reader stops reading its client meanwhile."""
        while len(self._pending) >= MAX_PENDING_SCRIPTS:
            self._room.clear()
            await self._room.wait()

    def _enqueue(self, item: _Arrival | _Action) -> None:
        self._pending.append(item)
        self._idle.clear()
        if self._worker is None:
            self._worker = asyncio.get_running_loop().create_task(self._work())

    async def _work(self) -> None:
        try:
            while self._pending:
                item = self._pending[0]
                if isinstance(item, _Arrival):
                    program = await self._compile(item.text)
                    if program is not None and item.number > self._dropped_through:
                        self.start(item.name, program)
                else:
                    self._acting_after = item.after
                    try:
                        item.action()
                    finally:
                        self._acting_after = None
                self._pending.popleft()
                if len(self._pending) < MAX_PENDING_SCRIPTS:
                    self._room.set()
        finally:
            self._worker = None
            self._room.set()
            self._idle.set()

    async def _compile(self, text: str) -> Any:
        from urdaemon.fakeur.urscript import ScriptCompileError, compile_program

        try:
            program = await asyncio.get_running_loop().run_in_executor(
                _COMPILER, _compile_briefly, compile_program, text, self.series, self.version
            )
        except ScriptCompileError as err:
            log.info("%s program refused at %d:%d: %s", self.address, err.line, err.column, err.message)
            self.broadcast(prim.RuntimeExceptionMessage(err.line, err.column, err.message))
            return None
        except Exception as err:  # the compiler's own fault refuses this program, and the queue goes on
            log.exception("%s program refused: the compiler failed", self.address)
            self.broadcast(prim.RuntimeExceptionMessage(1, 1, f"compile_error: {type(err).__name__}: {err}"))
            return None
        self.compiles += 1
        return program

    async def off_loop(self, work: Callable[..., Any], *args: Any) -> Any:
        """``work(*args)`` done in the compiler thread, as compiling is: pure-Python work that would
        hold every fake's clock on the event loop (a ``.urp`` translated at ``load``)."""
        return await asyncio.get_running_loop().run_in_executor(_COMPILER, _compile_briefly, work, *args)

    async def close(self) -> None:
        """Forget what waits to start, end every program."""
        self._pending.clear()
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await worker
        self.end_all()

    # ---- starting and ending -------------------------------------------------------------------------

    def start(self, name: str, program: Any) -> None:
        """Start a compiled program: a ``sec`` one beside the main one, any other replacing it."""
        if program.kind == "sec":
            host = self._host()
            self.secondary.append(RunningScript(name, program.start(host), host))
            return
        if self.main is not None:
            self.end(self.main)
        reason = self.arm.start_program()
        if reason is not None:
            self.broadcast(prim.TextMessage(f"program {name} not started: {reason}"))
            return
        host = self._host()
        self.main = RunningScript(name, program.start(host), host)
        self.name = name
        apply_runstate_outputs(self.arm, running=True)
        self.broadcast(prim.KeyMessage(0, 0, "PROGRAM_XXX_STARTED", name))

    def _host(self) -> ScriptHost:
        return ScriptHost(
            self.arm,
            step_time=self.step_time,
            series=self.series,
            version=self.version,
            local_address=self.address,  # a real robot's connections come from its own address
            message=self._message,
            input_registers=self.input_registers,
        )

    def _message(self, kind: str, text: str) -> None:
        if kind == "popup":
            self.broadcast(prim.popup_message(text))
        elif kind == "runtime":
            self.broadcast(prim.RuntimeExceptionMessage(0, 0, text))
        else:
            self.broadcast(prim.TextMessage(text))

    def stop(self) -> None:
        """``stop program``: every program ends and the arm stops; so do the scripts that arrived
        before it and still wait to be compiled (on a controller they would have started, then stopped)."""
        self._dropped_through = self._arrived if self._acting_after is None else self._acting_after
        self.end_all()
        self.arm.stop_program()

    def end(self, script: RunningScript) -> None:
        """``script`` ends (by itself, by an error or stopped): report why, close what it opened."""
        run = script.run
        if not run.done:
            with contextlib.suppress(Exception):
                run.stop()
        script.host.close()
        error = run.error
        if error is not None:
            log.info(
                "%s program %s: runtime error at %d:%d: %s",
                self.address,
                script.name,
                error.line,
                error.column,
                error.message,
            )
            self.broadcast(prim.RuntimeExceptionMessage(error.line, error.column, error.message))
        elif script.failure is not None:
            self.broadcast(prim.RuntimeExceptionMessage(0, 0, script.failure))
        if script in self.secondary:
            self.secondary.remove(script)
            return
        if self.main is script:
            self.main = None
            self.arm.stop_program()
            apply_runstate_outputs(self.arm, running=False)
        log.info("%s program %s ended", self.address, script.name)
        self.broadcast(prim.KeyMessage(0, 0, "PROGRAM_XXX_STOPPED", script.name))

    def end_all(self) -> None:
        for script in [*self.secondary, *([self.main] if self.main is not None else [])]:
            self.end(script)

    # ---- every cycle ---------------------------------------------------------------------------------

    def step(self) -> None:
        """One cycle: the main program while it plays or pauses (not once paused), then every ``sec``
        program; a program that has ended is closed; the main one's RTDE watchdogs are checked."""
        script = self.main
        if script is not None:
            state = self.arm.runtime_state
            if state is RuntimeState.PLAYING or state is RuntimeState.PAUSING:
                # while pausing the program's motion goes on in time slowed to 0 along its path
                self._step(script)
                if script.run.done or script.failure is not None:
                    self.end(script)
                elif state is RuntimeState.PLAYING:
                    self._check_watchdogs(script)
            elif state is RuntimeState.STOPPED:  # stopped from outside: power off, stop, ...
                self.end(script)
        for sec in list(self.secondary):
            self._step(sec)
            if sec.run.done or sec.failure is not None:
                self.end(sec)

    def _step(self, script: RunningScript) -> None:
        try:
            script.run.step()
        except Exception as err:  # the interpreter's own fault ends this program, not the controller
            log.exception("%s program %s: the interpreter failed", self.address, script.name)
            script.failure = f"{type(err).__name__}: {err}"

    def _check_watchdogs(self, script: RunningScript) -> None:
        watchdogs = script.host.watchdogs
        if not watchdogs:
            return
        now = self.arm.timestamp
        for watchdog in list(watchdogs.values()):
            if watchdog.min_frequency <= 0 or watchdog.action == "ignore":
                continue
            last = max(self.input_times.get(watchdog.variable, -math.inf), watchdog.since)
            if now - last <= 1.0 / watchdog.min_frequency + 1e-9:
                continue
            text = f"RTDE watchdog: {watchdog.variable} not updated at {watchdog.min_frequency:g} Hz"
            self.broadcast(prim.TextMessage(text))
            if watchdog.action == "pause":
                self.arm.pause_program()
            else:
                self.stop()
            return

    # ---- the External Control program ------------------------------------------------------------------

    async def play_urcap(self, urcap: tuple[str, int], start: Callable[[str, str], None]) -> None:
        """What the External Control URCap does on play: fetch the script, then ``start`` it."""
        host, port = urcap
        try:
            fetch = await connect(
                ScriptFetch,
                host,
                port,
                timeout=URCAP_TIMEOUT_S,
                name="External Control",
                local_addr=(self.address, 0),
            )
        except UrDaemonError as err:  # the URCap's popup names the socket's own error
            reason = err.__cause__ or err
            text = f"External Control: connection to {host}:{port} could not be established: {reason}"
            self.broadcast(prim.TextMessage(text))
            self.arm.stop_program()
            return
        try:
            text = await fetch.program()
        except ProtocolError as err:  # more than a script can be, or not UTF-8 text
            self.broadcast(prim.TextMessage(f"External Control: {err}"))
            self.arm.stop_program()
            return
        finally:
            fetch.close()
        self.arm.life.wait_for_script()
        start("externalControl", text)


class ScriptFetch(Shell):
    """The External Control URCap's fetch of the control script: the robot's side of the script sender
    (docs/protocols.md §4.3), which dials the daemon. It asks once, waits ``URCAP_TIMEOUT_S`` for the
    first line, then takes more lines only while each comes within ``URCAP_MORE_S`` of the last."""

    def __init__(self) -> None:
        super().__init__(
            script_sender.ScriptSenderConnection(Side.ROBOT), "script sender", peer_name="daemon"
        )
        self.lines = 0
        """Complete lines received so far."""
        self._news = asyncio.Event()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        self.send(script_sender.RequestProgram())

    def receive(self, data: bytes) -> list[Any]:
        self.lines += data.count(b"\n")
        self._news.set()
        return super().receive(data)

    def end(self, reason: Exception) -> None:
        super().end(reason)
        self._news.set()

    async def program(self) -> str:
        """The script's text as received (its lines with their newlines); TimeoutError if no first
        line comes in time, RemoteProtocolError if what came is no script."""
        await asyncio.wait_for(self._beyond(0), URCAP_TIMEOUT_S)
        while not self.closed.done():  # more lines only while they keep coming
            try:
                await asyncio.wait_for(self._beyond(self.lines), URCAP_MORE_S)
            except TimeoutError:
                break
        for event in self.codec.close():
            if isinstance(event, script_sender.ProgramReceived):
                return event.text + "\n"
            if isinstance(event, script_sender.ProgramIncomplete):
                return event.data.decode("utf-8", "replace")
        return ""

    async def _beyond(self, lines: int) -> None:
        """Until more than ``lines`` lines have come, or the connection ended."""
        while self.lines <= lines and not self.closed.done():
            self._news.clear()
            await self._news.wait()


COMPILE_SWITCH_INTERVAL_S = 0.0005
"""The GIL switch interval while a script compiles (Python's default: 5 ms)."""


def _compile_briefly(compile_program: Callable[..., Any], *args: Any) -> Any:
    """Compile (or other work) in the compiler thread, handing the GIL back often meanwhile.

    Parsing is pure Python: the event loop thread, which gives up the GIL at every system call (a
    timer read, a socket write), waits up to a whole switch interval to get it back each time, so with
    the default 5 ms a controller cycle of 2 ms is lost at almost every tick while a script compiles."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(min(previous, COMPILE_SWITCH_INTERVAL_S))
    collecting = gc.isenabled()
    gc.disable()
    try:
        return compile_program(*args)
    finally:
        if collecting:
            gc.enable()
        sys.setswitchinterval(previous)
