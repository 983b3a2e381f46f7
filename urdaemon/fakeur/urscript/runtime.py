"""The URScript runtime: values, builtin registry, errors and the scheduler (:class:`ScriptRun`).

Contract shared by every ``lib_*.py`` (see each function's docstring): builtins are registered with
:func:`builtin`, take the :class:`~urdaemon.fakeur.urscript.script_host.ScriptHost` first and then their
arguments positionally in the order of their signature in ``functions.yaml``, every default already
filled in by the compiler. A blocking builtin is a generator function: each bare ``yield`` gives up the
rest of the current controller cycle; its return value is the call's value.
"""

from __future__ import annotations

import operator
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from time import perf_counter
from typing import Any, Final

__all__ = [
    "BUILTINS",
    "MAIN",
    "PROGRAM_SLICE",
    "STALL_BUDGET_S",
    "THREAD_SLICE",
    "TOO_LONG",
    "Builtin",
    "ProgramHalt",
    "ScriptCompileError",
    "ScriptRun",
    "ScriptRuntimeError",
    "UrList",
    "UrPose",
    "UrStruct",
    "builtin",
    "copy_value",
]


class ScriptCompileError(Exception):
    """The controller refuses the whole program before it starts (line and column are 1-based)."""

    def __init__(self, line: int, column: int, message: str) -> None:
        super().__init__(f"{message} (line {line}, column {column})")
        self.line = line
        self.column = column
        self.message = message


class ScriptRuntimeError(Exception):
    """A fault while the program runs; the runtime adds the statement's line and column."""

    def __init__(self, message: str, line: int = 0, column: int = 0) -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.column = column


@dataclass(frozen=True, slots=True)
class Builtin:
    name: str
    function: Callable[..., Any]
    blocking: bool


BUILTINS: Final[dict[str, Builtin]] = {}
"""Every implemented builtin by name; filled by the lib_* modules when they are imported."""


def builtin(name: str, *, blocking: bool = False) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register ``function`` as the implementation of URScript builtin ``name``."""

    def register(function: Callable[..., Any]) -> Callable[..., Any]:
        if name in BUILTINS:
            raise ValueError(f"builtin {name} registered twice")
        BUILTINS[name] = Builtin(name, function, blocking)
        return function

    return register


class UrList(list[Any]):
    """A URScript list: ``+ - * /`` work element-wise, and with a scalar on either side."""

    __slots__ = ()

    def _zip(self, other: Any, op: Callable[[Any, Any], Any]) -> UrList:
        if isinstance(other, list):
            if len(other) != len(self):
                raise ScriptRuntimeError(f"lists of different lengths ({len(self)} and {len(other)})")
            return type(self)(map(op, self, other))
        return type(self)([op(a, other) for a in self])

    def _rzip(self, other: Any, op: Callable[[Any, Any], Any]) -> UrList:
        if isinstance(other, list):  # a plain list on the left: still element-wise
            if len(other) != len(self):
                raise ScriptRuntimeError(f"lists of different lengths ({len(other)} and {len(self)})")
            return type(self)(map(op, other, self))
        return type(self)([op(other, a) for a in self])

    def __add__(self, other: Any) -> UrList:
        return self._zip(other, operator.add)

    def __radd__(self, other: Any) -> UrList:
        return self._rzip(other, operator.add)

    def __sub__(self, other: Any) -> UrList:
        return self._zip(other, operator.sub)

    def __rsub__(self, other: Any) -> UrList:
        return self._rzip(other, operator.sub)

    def __mul__(self, other: Any) -> UrList:
        return self._zip(other, operator.mul)

    def __rmul__(self, other: Any) -> UrList:
        return self._rzip(other, operator.mul)

    def __truediv__(self, other: Any) -> UrList:
        return self._zip(other, operator.truediv)

    def __rtruediv__(self, other: Any) -> UrList:
        return self._rzip(other, operator.truediv)

    def __neg__(self) -> UrList:
        return type(self)(map(operator.neg, self))

    def __repr__(self) -> str:
        return "[" + ", ".join(map(_text, self)) + "]"


class UrPose(UrList):
    """A URScript pose ``p[x, y, z, rx, ry, rz]`` (metres, rotation vector in radians)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "p" + super().__repr__()


class UrStruct:
    """``struct(a=1, b=2)``: named fields read and written as ``s.a``."""

    def __init__(self, fields: Iterable[tuple[str, Any]]) -> None:
        for key, value in fields:
            setattr(self, key, value)

    def __repr__(self) -> str:
        return "struct(" + ", ".join(f"{k}={_text(v)}" for k, v in vars(self).items()) + ")"


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, float):
        return f"{value:.6g}"
    return repr(value) if isinstance(value, (list, UrStruct)) else str(value)


# -- the scheduler --------------------------------------------------------------------------------------

TOO_LONG: Final = (
    "The program used too much time without instructing the robot what to do. "
    "Consider using a Wait or sync() to split long program sequences that do not move the robot."
)
"""The controller's runtime error for a loop that cannot be put aside and runs too long in one cycle."""

THREAD_SLICE: Final = 0.1
"""The share of a controller cycle one thread may run for in it (0.2 ms at 2 ms, 0.8 ms at 8 ms) before
a loop puts it aside until the next cycle, as UR's scheduler puts a thread that used its time slice in
a non-runnable state until the next frame. Wall time, read at every iteration (``perf_counter``, about
50 ns): a costly builtin in the loop cannot overrun it by more than one call, and a fake preempted by a
busy machine gives up its slice sooner, never later."""
PROGRAM_SLICE: Final = 0.25
"""The share of a cycle all of one program's threads may run for together; a thread resumed after that
still runs, until its first loop check, so every runnable thread progresses every cycle."""
STALL_BUDGET_S: Final = 0.1
"""Processor time (the thread's own) a loop that cannot be put aside (one in a function that never
blocks) may use in one cycle before the program stops with :data:`TOO_LONG`."""

_DEFAULT: Final = object()
"""Marks a parameter left out whose default (a list, pose or struct) is made anew at each call."""

MAIN: Final = 0
"""The main program's thread handle."""


class ProgramHalt(BaseException):
    """``halt``: ends the whole program (a BaseException so no builtin swallows it)."""


class _Killed(BaseException):
    """The running thread killed itself."""


def copy_value(value: Any) -> Any:
    """A URScript value as a new variable holds it: lists and structs are values, not references."""
    kind = type(value)
    if kind is UrPose:
        return UrPose(value)
    if kind is UrList:
        for item in value:
            if isinstance(item, (list, UrStruct)):  # a matrix: its rows are values too
                return UrList(copy_value(v) for v in value)
        return UrList(value)
    if kind is UrStruct:
        return UrStruct((k, copy_value(v)) for k, v in vars(value).items())
    if isinstance(value, list):
        return UrList(copy_value(v) for v in value)
    return value


def _struct(fields: Iterable[tuple[str, Any]]) -> UrStruct:
    return UrStruct(fields)


class _Thread:
    __slots__ = ("generator", "handle")

    def __init__(self, handle: int, generator: Any) -> None:
        self.handle = handle
        self.generator = generator


class ScriptRun:
    """One run of a compiled program on one host: the controller calls :meth:`step` once per cycle.

    Each step resumes every live thread once, the main program first, then the threads in the order they
    were started (one started during this step runs in it too); a thread runs until it blocks, ends, or
    a loop finds its time slice of the cycle used (:data:`THREAD_SLICE`, within :data:`PROGRAM_SLICE`
    for the program): then it is put aside and resumes there next cycle. Only at a loop's check, so
    no thread is ever interrupted between two statements, so ``enter_critical``/``exit_critical``
    need no action: a critical section cannot be interleaved, and a thread that blocks inside one lets
    the others run (as on a real controller: UR's External Control script blocks in a socket read and in
    ``servoj`` inside critical sections, and its threads still share the cycle). The run is :attr:`done`
    once the main program ended, by returning, ``halt``, a runtime error (:attr:`error`) or :meth:`stop`.
    """

    def __init__(self, program: Any, host: Any) -> None:
        from functools import partial
        from itertools import count

        self.program = program
        self.host = host
        self._done = False
        self.error: ScriptRuntimeError | None = None
        self._threads: list[_Thread] = []
        self._alive: set[int] = set()
        self._next_handle = 1
        self._current: _Thread | None = None
        self._count = count
        namespace: dict[str, Any] = {
            "__builtins__": {},
            "_L": UrList,
            "_P": UrPose,
            "_S": _struct,
            "_cp": copy_value,
            "_f": float,
            "_b": bool,
            "_next": next,
            "_tick": count(),
            "_too_long": self._too_long,
            "_pc": perf_counter,
            "_end": 0.0,
            "_r": 0,
            "_stalled": self._stalled,
            "_D": _DEFAULT,
            "_start": self._start,
            "_kill": self._kill,
            "_join": self._join,
            "_halt": self._halt,
        }
        namespace.update(program.constants)
        for name, (function, _) in program.builtins.items():
            namespace["b_" + name] = partial(function, host)
        exec(program.code, namespace)
        self._namespace = namespace
        self._stall_start: float | None = None
        self._resumes = 0
        """Threads resumed so far: a loop tells by it whether its thread was put aside since it looked."""
        main = _Thread(MAIN, namespace["_main"]())
        self._threads.append(main)
        self._alive.add(MAIN)

    # -- the controller's side --------------------------------------------------------------------------

    def step(self) -> None:
        """One controller cycle."""
        if self.done:
            return
        threads = self._threads
        namespace = self._namespace
        host = self.host
        step_time = host.step_time
        slice_s = step_time * THREAD_SLICE
        program_end = perf_counter() + step_time * PROGRAM_SLICE
        index = 0
        while index < len(threads):
            thread = threads[index]
            index += 1
            host.thread = thread.handle
            namespace["_tick"] = self._count()
            self._current = thread
            namespace["_end"] = min(perf_counter() + slice_s, program_end)
            self._resumes += 1
            namespace["_r"] = self._resumes
            self._stall_start = None
            try:
                next(thread.generator)
            except StopIteration:
                self._ended(thread)
            except _Killed:
                self._ended(thread)
            except ProgramHalt:
                self._finish()
            except ScriptRuntimeError as error:
                self._fail(error, error.__traceback__)
            except Exception as error:
                self._fail(ScriptRuntimeError(_describe(error)), error.__traceback__)
            self._current = None
            if self._done:
                return
        if len(threads) != len(self._alive):
            self._threads = [t for t in threads if t.handle in self._alive]

    @property
    def done(self) -> bool:
        """True once the main program ended (returned, halt, a runtime error or :meth:`stop`)."""
        return self._done

    def stop(self) -> None:
        """The controller stops the program (stop program, a new program replacing it...)."""
        self._finish()

    def variable(self, name: str) -> Any:
        """The current value of the program's variable ``name``: a program-level or ``global`` one.

        Raises ``KeyError(name)`` if the program has no such variable, or has not given it a value yet.
        A function's locals are not visible (they live only while the function runs).
        """
        try:
            return self._namespace["v_" + name]
        except KeyError:
            raise KeyError(name) from None

    @property
    def threads(self) -> tuple[int, ...]:
        """Handles of the live threads, main (0) first."""
        return tuple(t.handle for t in self._threads if t.handle in self._alive)

    def _ended(self, thread: _Thread) -> None:
        self._alive.discard(thread.handle)
        if thread.handle == MAIN:
            self._finish()

    def _finish(self) -> None:
        if self._done:
            return
        self._done = True
        current = self._current
        for thread in self._threads:
            if thread is not current:
                thread.generator.close()
        self._alive.clear()

    def _fail(self, error: ScriptRuntimeError, traceback: Any) -> None:
        if not error.line:
            error.line, error.column = self._position(traceback)
        self.error = error
        self._finish()

    def _position(self, traceback: Any) -> tuple[int, int]:
        position = (0, 0)
        code = self.program.code
        while traceback is not None:
            if traceback.tb_frame.f_code.co_filename == code.co_filename:
                position = self.program.lines.get(traceback.tb_lineno, position)
            traceback = traceback.tb_next
        return position

    # -- called by the generated code -------------------------------------------------------------------

    def _too_long(self) -> None:
        raise ScriptRuntimeError(TOO_LONG)

    def _stalled(self) -> bool:
        """A loop that cannot be put aside has used :data:`STALL_BUDGET_S` of processor time since its
        thread was resumed (counted from its first check, 256 iterations in)."""
        now = time.thread_time()
        if self._stall_start is None:
            self._stall_start = now
            return False
        return now - self._stall_start > STALL_BUDGET_S

    def _start(self, function: Callable[[], Any]) -> int:
        handle = self._next_handle
        self._next_handle += 1
        self._threads.append(_Thread(handle, function()))
        self._alive.add(handle)
        return handle

    def _kill(self, handle: Any) -> None:
        if handle not in self._alive or handle == MAIN:
            return
        current = self._current
        if current is not None and current.handle == handle:
            raise _Killed
        self._alive.discard(handle)
        for thread in self._threads:
            if thread.handle == handle:
                thread.generator.close()

    def _join(self, handle: Any) -> Iterator[None]:
        if self._current is not None and handle == self._current.handle and handle != MAIN:
            raise ScriptRuntimeError("join: a thread cannot wait for itself to end")
        while handle in self._alive and handle != MAIN:
            yield

    def _halt(self) -> None:
        raise ProgramHalt


def _describe(error: Exception) -> str:
    """The controller's kind of message for a Python fault raised by a script's own operations."""
    if isinstance(error, NameError):
        name = getattr(error, "name", None) or str(error).split("'")[1 if "'" in str(error) else 0]
        return f"Variable '{name.removeprefix('v_')}' is used before it is given a value"
    if isinstance(error, IndexError):
        return "Index out of bounds"
    if isinstance(error, ZeroDivisionError):
        return "Division by zero"
    if isinstance(error, RecursionError):
        return "Stack overflow: functions call each other too deeply"
    if isinstance(error, AttributeError):
        return f"Struct has no such field: {error}"
    if isinstance(error, TypeError):
        return f"Type error: {error}"
    return f"{type(error).__name__}: {error}"
