"""The URScript runtime: values, builtin registry, errors and (to come) the scheduler.

Contract shared by every ``lib_*.py`` (see each function's docstring): builtins are registered with
:func:`builtin`, take the :class:`~urdaemon.fakeur.urscript.host.ScriptHost` first and then their
arguments positionally in the order of their signature in ``functions.yaml``, every default already
filled in by the compiler. A blocking builtin is a generator function: each bare ``yield`` gives up the
rest of the current controller cycle; its return value is the call's value.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Final

__all__ = [
    "BUILTINS",
    "Builtin",
    "ScriptCompileError",
    "ScriptRuntimeError",
    "UrList",
    "UrPose",
    "UrStruct",
    "builtin",
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
            return type(self)(op(a, b) for a, b in zip(self, other, strict=True))
        return type(self)(op(a, other) for a in self)

    def _rzip(self, other: Any, op: Callable[[Any, Any], Any]) -> UrList:
        return type(self)(op(other, a) for a in self)

    def __add__(self, other: Any) -> UrList:
        return self._zip(other, lambda a, b: a + b)

    def __radd__(self, other: Any) -> UrList:
        return self._rzip(other, lambda a, b: a + b)

    def __sub__(self, other: Any) -> UrList:
        return self._zip(other, lambda a, b: a - b)

    def __rsub__(self, other: Any) -> UrList:
        return self._rzip(other, lambda a, b: a - b)

    def __mul__(self, other: Any) -> UrList:
        return self._zip(other, lambda a, b: a * b)

    def __rmul__(self, other: Any) -> UrList:
        return self._rzip(other, lambda a, b: a * b)

    def __truediv__(self, other: Any) -> UrList:
        return self._zip(other, lambda a, b: a / b)

    def __rtruediv__(self, other: Any) -> UrList:
        return self._rzip(other, lambda a, b: a / b)

    def __neg__(self) -> UrList:
        return type(self)(-a for a in self)

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
