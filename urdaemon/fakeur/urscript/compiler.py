"""URScript AST -> checked, compiled Python: ``compile_program(text, series, version)``.

Compiling is the controller's: the whole program is refused (:class:`ScriptCompileError` with line and
column) for a syntax error, a non-ASCII character, an unknown function or variable, a wrong argument
count, an unknown keyword argument, a socket name no ``socket_open`` of the program opens, a builtin this
series/version does not have, or a physical builtin in a ``sec`` program.

The checks and the names they resolve are fakeur/urscript/checker.py (:class:`Checker`). Then every
URScript function and thread becomes one Python function of a generated module (fakeur/urscript/codegen.py,
:class:`CodeGenerator`), compiled here once per program text and bound to the builtins it calls.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from types import CodeType
from typing import TYPE_CHECKING, Any, Final

import urdaemon.fakeur.urscript.syntax as ast
from urdaemon.fakeur.urscript.checker import Checker
from urdaemon.fakeur.urscript.codegen import CodeGenerator
from urdaemon.fakeur.urscript.runtime import (
    BUILTINS,
    Builtin,
    ScriptCompileError,
    ScriptRun,
    ScriptRuntimeError,
)
from urdaemon.fakeur.urscript.signatures import all_signatures, load_signatures

if TYPE_CHECKING:
    from urdaemon.fakeur.urscript.script_host import ScriptHost

__all__ = ["MAX_PROGRAM_CHARS", "Program", "compile_program"]

MAX_PROGRAM_CHARS: Final = 256 * 1024
"""The longest program the fake compiles. Python's own compile step holds the interpreter lock
(~0.4 s per MiB of program), stalling every fake's clock in the process; our control script is 25 KB,
ur_rtde's 42 KB, so this leaves ample room while bounding that stall (~0.1 s) for a hostile client."""

_FILENAME: Final = "<urscript>"


@dataclass
class Program:
    """A compiled URScript program; ``start(host)`` gives a run (nothing runs before its first step)."""

    kind: str  # "def", "sec" or "line"
    name: str
    code: CodeType
    lines: dict[int, tuple[int, int]]
    """Generated Python line -> the URScript (line, column) of its statement."""
    builtins: dict[str, tuple[Callable[..., Any], bool]]
    """Builtin name -> (implementation taking the host first, blocking)."""
    constants: dict[str, object]
    source: str = field(repr=False)

    def start(self, host: ScriptHost) -> ScriptRun:
        return ScriptRun(self, host)


def _not_simulated(name: str) -> Callable[..., Any]:
    def missing(host: Any, *args: Any) -> Any:
        raise ScriptRuntimeError(f"{name}: not simulated by the fake controller")

    return missing


def _unsupported(name: str, series: str, version: tuple[int, int]) -> Callable[..., Any]:
    controller = f"{'e-Series' if series == 'e' else series.upper()} {version[0]}.{version[1]}"

    def unsupported(host: Any, *args: Any) -> Any:
        raise ScriptRuntimeError(f"{name}: not available on this controller ({controller})")

    return unsupported


def compile_program(
    text: str,
    series: str = "e",
    version: tuple[int, int] = (5, 12),
    *,
    signatures: Mapping[str, Any] | None = None,
    builtins: Mapping[str, Builtin] | None = None,
) -> Program:
    """Check ``text`` and compile it; raise :class:`ScriptCompileError` (line, column) if refused.

    ``signatures``: the builtin table (name -> Signature) to check against; by default the table of
    ``functions.yaml`` for ``series``/``version``. ``builtins``: the implementations (default: the
    registry :data:`~urdaemon.fakeur.urscript.runtime.BUILTINS`); a tabled name without one compiles and
    stops the program with "not simulated" when called.

    Compiling takes tens to hundreds of milliseconds (parsing); a program compiled with the default
    table and registry is cached by its text, series and version (a daemon re-sends the same script), and
    a Program is never changed by running it.
    """
    try:
        if signatures is None and builtins is None:
            return _compile_default(text, series, version)
        return _compile(text, series, version, signatures, builtins)
    except RecursionError:
        raise ScriptCompileError(1, 1, "compile_error: expressions or blocks nested too deeply") from None


@lru_cache(maxsize=16)
def _compile_default(text: str, series: str, version: tuple[int, int]) -> Program:
    return _compile(text, series, version, None, None)


def _compile(
    text: str,
    series: str,
    version: tuple[int, int],
    signatures: Mapping[str, Any] | None,
    builtins: Mapping[str, Builtin] | None,
) -> Program:
    if len(text) > MAX_PROGRAM_CHARS:
        raise ScriptCompileError(
            1,
            1,
            f"compile_error: program of {len(text)} characters; the fake compiles at most "
            f"{MAX_PROGRAM_CHARS}",
        )
    items = ast.parse(text)
    known_anywhere: Mapping[str, Any] = {}
    if signatures is None:
        signatures = load_signatures(series, version)
        known_anywhere = all_signatures()
    kind, name, body = _program_body(items)
    implementations = BUILTINS if builtins is None else builtins
    checker = Checker(kind, body, signatures, known_anywhere, implementations)
    checker.check()
    generator = CodeGenerator(checker)
    source, lines, used, constants = generator.generate()
    bound: dict[str, tuple[Callable[..., Any], bool]] = {}
    for builtin_name in used:
        implementation = checker.implementation(builtin_name)
        if not getattr(signatures[builtin_name], "supported", True):
            bound[builtin_name] = (_unsupported(builtin_name, series, version), False)
        elif implementation is None:
            bound[builtin_name] = (_not_simulated(builtin_name), False)
        else:
            bound[builtin_name] = (implementation.function, implementation.blocking)
    for io_name in generator.used_io:
        io_builtin = implementations.get(io_name)
        bound[io_name] = (_not_simulated(io_name) if io_builtin is None else io_builtin.function, False)
    try:
        code = compile(source, _FILENAME, "exec")
    except SyntaxError as error:  # a limit of Python's compiler, e.g. more than 20 nested loops
        line, column = lines.get(error.lineno or 0, (1, 1))
        raise ScriptCompileError(line, column, f"compile_error: {error.msg}") from None
    return Program(kind, name, code, lines, bound, constants, source)


def _program_body(items: tuple[Any, ...]) -> tuple[str, str, tuple[Any, ...]]:
    if len(items) == 1 and isinstance(items[0], ast.Function) and items[0].kind in ("def", "sec"):
        only = items[0]
        if only.params:
            raise ScriptCompileError(only.line, only.column, f"program {only.name} may not take parameters")
        return only.kind, only.name, only.body
    return "line", "", items
