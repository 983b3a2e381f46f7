"""URScript AST -> checked, compiled Python: ``compile_program(text, series, version)``.

Compiling is the controller's: the whole program is refused (:class:`ScriptCompileError` with line and
column) for a syntax error, a non-ASCII character, an unknown function or variable, a wrong argument
count, an unknown keyword argument, a socket name no ``socket_open`` of the program opens, a builtin this
series/version does not have, or a physical builtin in a ``sec`` program.

Then every URScript function and thread becomes one Python function of a generated module, compiled once
(:class:`_Generator`): those that may block are generators called with ``yield from``; the others stay
plain functions. Names are prefixed (``v_`` variables, ``f_`` functions, ``t_`` threads, ``b_`` builtins)
so no URScript name can clash with Python's.
"""

from __future__ import annotations

import keyword
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from types import CodeType
from typing import TYPE_CHECKING, Any, Final

from urdaemon.fakeur.urscript import syntax as ast
from urdaemon.fakeur.urscript.lib_io import IO_DIGITAL_IN_GET, IO_DIGITAL_OUT_GET, IO_DIGITAL_OUT_SET
from urdaemon.fakeur.urscript.runtime import BUILTINS, Builtin, ScriptCompileError

if TYPE_CHECKING:
    from urdaemon.fakeur.urscript.host import ScriptHost
    from urdaemon.fakeur.urscript.runtime import ScriptRun

__all__ = [
    "CONSTANTS",
    "IO_VARIABLES",
    "MAX_OPS_PER_CYCLE",
    "MAX_PROGRAM_CHARS",
    "Program",
    "compile_program",
]

MAX_OPS_PER_CYCLE: Final = 100_000
"""Loop iterations one thread may run in one controller cycle. Past it, a loop that may wait (it calls a
blocking builtin that happened not to block) puts its thread aside until the next cycle, as the
controller's scheduler does with a thread that used up its time slice; a loop that can never wait
stops the program with the controller's error."""

MAX_PROGRAM_CHARS: Final = 256 * 1024
"""The longest program the fake compiles. Python's own compile step holds the interpreter lock
(~0.4 s per MiB of program), stalling every fake's clock in the process; our control script is 25 KB,
ur_rtde's 42 KB, so this leaves ample room while bounding that stall (~0.1 s) for a hostile client."""

_SPENT: Final = f"(_n := _next(_tick)) > {MAX_OPS_PER_CYCLE} or (_n & 255 == 0 and _late())"
"""A loop's test, each iteration, of whether its thread has used its time slice (inline: it is hot)."""

CONSTANTS: Final[dict[str, object]] = {"pi": 3.141592653589793}
"""Builtin variables of the language."""

IO_VARIABLES: Final[dict[str, tuple[str, str | None]]] = {
    "digital_out": (IO_DIGITAL_OUT_GET, IO_DIGITAL_OUT_SET),
    "digital_in": (IO_DIGITAL_IN_GET, None),
}
"""The controller's legacy IO variables: name -> (reader, writer or None if read-only), lib_io builtins.

``digital_out[n]`` (read and assigned) and ``digital_in[n]`` (read) are the IO as CB2-era programs
address it, still accepted by CB3 controllers: python-urx's ``set_digital_out`` sends
``digital_out[2]=True``, which drove a CB3's outputs (python-urx issue #8). They act on the arm's IO, as
``set_standard_digital_out`` does (numbering: lib_io). Only the indexed form ``name[n]`` is accepted.

A program's own variable of the same name shadows the controller's (a program-level assignment
``digital_out = [...]``, a ``global``/``local`` declaration, a parameter or a local): the name is then
the program's variable everywhere it is visible, as a program's own name shadows any builtin variable.
"""

DEFAULT_SOCKET: Final = "socket_0"
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
        from urdaemon.fakeur.urscript.runtime import ScriptRun

        return ScriptRun(self, host)


def _not_simulated(name: str) -> Callable[..., Any]:
    def missing(host: Any, *args: Any) -> Any:
        from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError

        raise ScriptRuntimeError(f"{name}: not simulated by the fake controller")

    return missing


def _unsupported(name: str, series: str, version: tuple[int, int]) -> Callable[..., Any]:
    controller = f"{'e-Series' if series == 'e' else series.upper()} {version[0]}.{version[1]}"

    def unsupported(host: Any, *args: Any) -> Any:
        from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError

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
        from urdaemon.fakeur.urscript import signatures as table

        signatures = table.load_signatures(series, version)
        known_anywhere = table.all_signatures()
    kind, name, body = _program_body(items)
    implementations = BUILTINS if builtins is None else builtins
    checker = _Checker(kind, body, signatures, known_anywhere, implementations)
    checker.check()
    generator = _Generator(checker)
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


# -- scopes ---------------------------------------------------------------------------------------------


def walk_statements(body: tuple[Any, ...], *, into_functions: bool = False) -> Iterator[Any]:
    """Every statement of ``body``, nested blocks included (function bodies only if asked)."""
    for statement in body:
        yield statement
        if isinstance(statement, ast.If):
            for _, block in statement.branches:
                yield from walk_statements(block, into_functions=into_functions)
            if statement.orelse:
                yield from walk_statements(statement.orelse, into_functions=into_functions)
        elif isinstance(statement, ast.While):
            yield from walk_statements(statement.body, into_functions=into_functions)
        elif isinstance(statement, ast.Function) and into_functions:
            yield from walk_statements(statement.body, into_functions=True)


def walk_expressions(node: Any) -> Iterator[Any]:
    """``node`` (an expression) and every expression inside it."""
    yield node
    if isinstance(node, ast.ListLiteral):
        for item in node.items:
            yield from walk_expressions(item)
    elif isinstance(node, ast.Index):
        yield from walk_expressions(node.base)
        for index in node.indices:
            yield from walk_expressions(index)
    elif isinstance(node, ast.Attribute):
        yield from walk_expressions(node.base)
    elif isinstance(node, ast.Call):
        for arg in node.args:
            yield from walk_expressions(arg)
        for keyword in node.keywords:
            yield from walk_expressions(keyword.value)
    elif isinstance(node, ast.Unary):
        yield from walk_expressions(node.operand)
    elif isinstance(node, ast.Binary):
        yield from walk_expressions(node.left)
        yield from walk_expressions(node.right)


def statement_expressions(statement: Any) -> Iterator[Any]:
    """The expressions a statement evaluates itself (not those of nested blocks)."""
    if isinstance(statement, ast.Assign):
        yield statement.value
        target: Any = statement.target
        while isinstance(target, (ast.Index, ast.Attribute)):
            if isinstance(target, ast.Index):
                yield from target.indices
            target = target.base
    elif isinstance(statement, ast.Declare):
        if statement.value is not None:
            yield statement.value
    elif isinstance(statement, ast.ExprStatement):
        yield statement.value
    elif isinstance(statement, ast.If):
        for condition, _ in statement.branches:
            yield condition
    elif isinstance(statement, ast.While):
        yield statement.condition
    elif isinstance(statement, ast.Return):
        if statement.value is not None:
            yield statement.value
    elif isinstance(statement, (ast.Kill, ast.Join)):
        yield statement.handle


def target_root(target: Any) -> str | None:
    while isinstance(target, (ast.Index, ast.Attribute)):
        target = target.base
    return target.name if isinstance(target, ast.Name) else None


@dataclass
class Scope:
    """One function's (or the program's) names: its locals; every other name read is a global."""

    function: ast.Function | None
    locals: set[str]
    body: tuple[Any, ...]


class _Checker:
    """Name resolution and the controller's static checks; what code generation works from."""

    def __init__(
        self,
        kind: str,
        body: tuple[Any, ...],
        signatures: Mapping[str, Any],
        known_anywhere: Mapping[str, Any],
        implementations: Mapping[str, Builtin],
    ) -> None:
        self.kind = kind
        self.implementations = implementations
        self.signatures = signatures
        self.known_anywhere = known_anywhere
        self.functions: dict[str, ast.Function] = {}
        self.duplicates: list[ast.Function] = []
        """Second definitions of a name: refused (the controller keeps one function per name)."""
        for statement in walk_statements(body, into_functions=True):
            if isinstance(statement, ast.Function):
                if statement.name in self.functions:
                    self.duplicates.append(statement)
                else:
                    self.functions[statement.name] = statement
        self.main_body = tuple(s for s in body if not isinstance(s, ast.Function))
        self.globals: set[str] = set()
        for statement in walk_statements(self.main_body):
            if isinstance(statement, ast.Assign) and isinstance(statement.target, ast.Name):
                self.globals.add(statement.target.name)
            elif isinstance(statement, ast.Declare):
                self.globals.add(statement.name)
        for statement in walk_statements(body, into_functions=True):
            if isinstance(statement, ast.Declare) and statement.scope == "global":
                self.globals.add(statement.name)
        self.mutated: set[str] = set()
        for statement in walk_statements(body, into_functions=True):
            if isinstance(statement, ast.Assign) and not isinstance(statement.target, ast.Name):
                root = target_root(statement.target)
                if root is not None:
                    self.mutated.add(root)
        self.scopes: dict[str, Scope] = {name: self._scope(f) for name, f in self.functions.items()}
        self.main = Scope(None, set(), self.main_body)
        self.errors: list[ScriptCompileError] = []
        self.opened_sockets: set[str] | None = {DEFAULT_SOCKET}
        self.blocking: set[str] = set()

    def _scope(self, function: ast.Function) -> Scope:
        names = {p.name for p in function.params}
        own_body = tuple(s for s in function.body if not isinstance(s, ast.Function))
        for statement in walk_statements(own_body):
            if isinstance(statement, ast.Declare) and statement.scope == "local":
                names.add(statement.name)
        for statement in walk_statements(own_body):
            target = statement.target if isinstance(statement, ast.Assign) else None
            if isinstance(target, ast.Name) and target.name not in self.globals:
                names.add(target.name)
        params = {p.name for p in function.params}
        for statement in walk_statements(own_body):
            if (
                isinstance(statement, ast.Declare)
                and statement.scope == "global"
                and statement.name not in params
            ):
                names.discard(statement.name)
        return Scope(function, names, own_body)

    # -- checks -----------------------------------------------------------------------------------------

    def error(self, node: Any, message: str) -> None:
        self.errors.append(ScriptCompileError(node.line, node.column, message))

    def check(self) -> None:
        for duplicate in self.duplicates:
            self.error(duplicate, f"compile_error: {duplicate.name} is already defined")
        self._collect_sockets()
        for scope in (self.main, *self.scopes.values()):
            self._check_scope(scope)
        self._find_blocking()
        if self.errors:
            raise min(self.errors, key=lambda e: (e.line, e.column))

    def all_scopes(self) -> Iterator[Scope]:
        yield self.main
        yield from self.scopes.values()

    def _collect_sockets(self) -> None:
        """The socket names the program's socket_open calls name; None if one takes its name at run time
        (urcl's script opens its sockets through a function with the name as a parameter)."""
        for scope in self.all_scopes():
            for call in self._calls(scope):
                if call.name == "socket_open" and call.name not in self.functions:
                    name = self._socket_argument(call)
                    if isinstance(name, ast.String):
                        if self.opened_sockets is not None:
                            self.opened_sockets.add(name.value)
                    elif name is not None:
                        self.opened_sockets = None

    def _calls(self, scope: Scope) -> Iterator[ast.Call]:
        for statement in walk_statements(scope.body):
            for expression in statement_expressions(statement):
                for node in walk_expressions(expression):
                    if isinstance(node, ast.Call):
                        yield node

    def _socket_argument(self, call: ast.Call) -> Any:
        signature = self.signatures.get(call.name)
        if signature is None:
            return None
        names = [p.name for p in signature.params]
        if "socket_name" not in names:
            return None
        for given in call.keywords:
            if given.name == "socket_name":
                return given.value
        position = names.index("socket_name")
        if position < len(call.args):
            return call.args[position]
        return None

    def _check_scope(self, scope: Scope) -> None:
        function = scope.function
        if function is not None:
            for param in function.params:
                if param.default is not None and not self._constant(scope, param.default):
                    self.error(param.default, f"default of parameter {param.name} must be a constant")
            if function.kind == "thread" and function.params:
                self.error(function, f"thread {function.name} may not take parameters")
        for statement in walk_statements(scope.body):
            if isinstance(statement, (ast.Break, ast.Continue)) and not self._inside_loop(scope, statement):
                self.error(statement, f"{type(statement).__name__.lower()} outside a loop")
            for expression in statement_expressions(statement):
                self._check_expression(scope, expression)
            if isinstance(statement, ast.Assign):
                self._check_target(scope, statement.target)

    def _constant(self, scope: Scope, node: Any) -> bool:
        """A literal: number, string, boolean, or a list or pose of literals (defaults must be)."""
        if isinstance(node, (ast.Number, ast.String, ast.Bool)):
            return True
        if isinstance(node, ast.Unary) and node.op in "+-":
            return isinstance(node.operand, ast.Number)
        if isinstance(node, ast.ListLiteral):
            return all(self._constant(scope, item) for item in node.items)
        if isinstance(node, ast.Index) and self.is_pose(scope, node):
            return len(node.indices) == 6 and all(self._constant(scope, item) for item in node.indices)
        return False

    def _inside_loop(self, scope: Scope, wanted: Any) -> bool:
        def search(body: tuple[Any, ...], in_loop: bool) -> bool | None:
            for statement in body:
                if statement is wanted:
                    return in_loop
                if isinstance(statement, ast.If):
                    for _, block in statement.branches:
                        found = search(block, in_loop)
                        if found is not None:
                            return found
                    if statement.orelse:
                        found = search(statement.orelse, in_loop)
                        if found is not None:
                            return found
                elif isinstance(statement, ast.While):
                    found = search(statement.body, True)
                    if found is not None:
                        return found
            return None

        return bool(search(scope.body, False))

    def _check_target(self, scope: Scope, target: Any) -> None:
        if isinstance(target, (ast.Index, ast.Attribute)):
            root = target_root(target)
            if root in IO_VARIABLES and not self.is_variable(scope, root):
                name = self.io_variable(scope, target)
                if name is None or IO_VARIABLES[name][1] is None:
                    self.error(target, f"compile_error: the controller's {root}[n] cannot be assigned")
                return
            if root is not None and not self.is_variable(scope, root):
                self.error(target, f"compile_error_name_not_found:{root}:")

    def is_variable(self, scope: Scope, name: str) -> bool:
        return name in scope.locals or name in self.globals

    def io_variable(self, scope: Scope, node: Any) -> str | None:
        """The controller IO variable ``node`` (``digital_out[n]``) uses, None if it is no such use."""
        if not isinstance(node, ast.Index) or len(node.indices) != 1:
            return None
        base = node.base
        if not isinstance(base, ast.Name) or base.name not in IO_VARIABLES:
            return None
        return None if self.is_variable(scope, base.name) else base.name

    def is_pose(self, scope: Scope, node: ast.Index) -> bool:
        """``p[...]`` is a pose literal unless ``p`` is a variable indexed with one index."""
        base = node.base
        if not isinstance(base, ast.Name) or base.name != "p":
            return False
        return len(node.indices) != 1 or not self.is_variable(scope, "p")

    def _check_expression(self, scope: Scope, expression: Any) -> None:
        pose_bases = set()
        for node in walk_expressions(expression):
            if isinstance(node, ast.Index) and (
                self.is_pose(scope, node) or self.io_variable(scope, node) is not None
            ):
                pose_bases.add(id(node.base))
        for node in walk_expressions(expression):
            if isinstance(node, ast.Name):
                if id(node) not in pose_bases and node.name in IO_VARIABLES:
                    if not self.is_variable(scope, node.name):
                        detail = f" (the controller's {node.name} is read as {node.name}[n])"
                        self.error(node, f"compile_error_name_not_found:{node.name}:{detail}")
                elif (
                    id(node) not in pose_bases
                    and not self.is_variable(scope, node.name)
                    and node.name not in CONSTANTS
                ):
                    self.error(node, f"compile_error_name_not_found:{node.name}:")
            elif isinstance(node, ast.Index) and self.is_pose(scope, node):
                if len(node.indices) != 6:
                    self.error(node, f"a pose p[...] takes 6 numbers, not {len(node.indices)}")
            elif isinstance(node, ast.Call):
                self._check_call(scope, node)
            elif isinstance(node, ast.Run):
                thread = self.functions.get(node.name)
                if thread is None or thread.kind != "thread":
                    self.error(node, f"compile_error_name_not_found:{node.name}: (no such thread)")

    def _check_call(self, scope: Scope, call: ast.Call) -> None:
        if call.name == "struct" and call.name not in self.functions:
            if call.args:
                self.error(call, "struct() takes only named fields: struct(name=value, ...)")
            return
        function = self.functions.get(call.name)
        if function is not None:
            if function.kind == "thread":
                self.error(call, f"thread {call.name} is started with run, not called")
                return
            self.bind_arguments(call, [(p.name, p.default is not None) for p in function.params])
            return
        signature = self.signatures.get(call.name)
        if signature is None:
            detail = ""
            if call.name in self.known_anywhere:
                detail = " (not available on this controller series/version)"
            self.error(call, f"compile_error_name_not_found:{call.name}:{detail}")
            return
        self.bind_arguments(call, [(p.name, not p.required) for p in signature.params])
        if self.kind == "sec" and signature.physical:
            self.error(call, f"{call.name} takes time on the arm: a sec program may not call it")
        if call.name.startswith("socket_") and call.name != "socket_open":
            name = self._socket_argument(call)
            opened = self.opened_sockets
            if opened is not None and isinstance(name, ast.String) and name.value not in opened:
                self.error(name, f'socket "{name.value}" is not opened by any socket_open of the program')

    def bind_arguments(self, call: ast.Call, params: list[tuple[str, bool]]) -> list[Any] | None:
        """The call's arguments in parameter order (None: take the default); errors are recorded."""
        if len(call.args) > len(params):
            self.error(
                call,
                f"wrong number of arguments for {call.name}: {len(call.args)} given, at most {len(params)}",
            )
            return None
        bound: list[Any] = list(call.args) + [None] * (len(params) - len(call.args))
        names = [name for name, _ in params]
        for given in call.keywords:
            if given.name not in names:
                self.error(given, f"unknown keyword argument {given.name} for {call.name}")
                return None
            position = names.index(given.name)
            if bound[position] is not None:
                self.error(given, f"argument {given.name} of {call.name} given twice")
                return None
            bound[position] = given.value
        for (name, optional), value in zip(params, bound, strict=True):
            if value is None and not optional:
                self.error(call, f"wrong number of arguments for {call.name}: missing {name}")
                return None
        return bound

    # -- which functions block --------------------------------------------------------------------------

    def implementation(self, name: str) -> Builtin | None:
        """The builtin's implementation, None if not simulated or not on this controller."""
        if not getattr(self.signatures[name], "supported", True):
            return None
        return self.implementations.get(name)

    def builtin_blocks(self, name: str) -> bool:
        implementation = self.implementation(name) if name in self.signatures else None
        return implementation is not None and implementation.blocking

    def body_blocks(self, body: tuple[Any, ...]) -> bool:
        """Whether running ``body`` may block: a join, a blocking builtin or a function that blocks."""
        for statement in walk_statements(body):
            if isinstance(statement, ast.Join):
                return True
            for expression in statement_expressions(statement):
                for node in walk_expressions(expression):
                    if isinstance(node, ast.Call) and (
                        node.name in self.blocking
                        if node.name in self.functions
                        else self.builtin_blocks(node.name)
                    ):
                        return True
        return False

    def _find_blocking(self) -> None:
        direct: dict[str, set[str]] = {}
        for name, scope in self.scopes.items():
            callees: set[str] = set()
            blocks = False
            for statement in walk_statements(scope.body):
                if isinstance(statement, ast.Join):
                    blocks = True
            for call in self._calls(scope):
                if call.name in self.functions:
                    callees.add(call.name)
                elif self.builtin_blocks(call.name):
                    blocks = True
            if blocks:
                self.blocking.add(name)
            direct[name] = callees
        changed = True
        while changed:
            changed = False
            for name, callees in direct.items():
                if name not in self.blocking and callees & self.blocking:
                    self.blocking.add(name)
                    changed = True


# -- code generation ------------------------------------------------------------------------------------

_BINARY: Final[dict[str, str]] = {"or": "or", "and": "and"}
_INDENT: Final = "    "


def _is_read(node: Any) -> bool:
    """An expression whose value may be another variable's list or struct (not a fresh one)."""
    return isinstance(node, (ast.Name, ast.Index, ast.Attribute))


class _Generator:
    """Python source for a checked program, one statement per line, with its line table."""

    def __init__(self, checker: _Checker) -> None:
        self.checker = checker
        self.out: list[str] = []
        self.lines: dict[int, tuple[int, int]] = {}
        self.used: set[str] = set()
        self.used_io: set[str] = set()
        """Registry names of the IO variables' readers and writers the program uses."""
        self.constants: dict[str, object] = {}
        self.scope = checker.main

    def generate(self) -> tuple[str, dict[int, tuple[int, int]], set[str], dict[str, object]]:
        for name, function in self.checker.functions.items():
            self.scope = self.checker.scopes[name]
            self._function(function)
        self.scope = self.checker.main
        self._emit(0, "def _main():", None)
        self._globals(1, self.checker.main_body)
        self._block(1, self.checker.main_body)
        self._emit(1, "return", None)
        self._emit(1, "yield", None)
        return "\n".join(self.out) + "\n", self.lines, self.used, self.constants

    def _emit(self, indent: int, text: str, node: Any) -> None:
        self.out.append(_INDENT * indent + text)
        if node is not None:
            self.lines[len(self.out)] = (node.line, node.column)

    def _globals(self, indent: int, body: tuple[Any, ...]) -> None:
        assigned = set()
        for statement in walk_statements(body):
            if isinstance(statement, ast.Assign) and isinstance(statement.target, ast.Name):
                assigned.add(statement.target.name)
            elif isinstance(statement, ast.Declare):
                assigned.add(statement.name)
        names = sorted(n for n in assigned if n not in self.scope.locals)
        if names:
            self._emit(indent, "global " + ", ".join("v_" + n for n in names), None)

    def _function(self, function: ast.Function) -> None:
        params = []
        fresh: list[tuple[str, str]] = []
        for param in function.params:
            if param.default is None:
                params.append(f"v_{param.name}")
            elif isinstance(param.default, (ast.ListLiteral, ast.Call)):
                # a list, pose or struct default is made anew at every call, not shared between calls
                params.append(f"v_{param.name}=_D")
                fresh.append((param.name, self._expr(param.default)))
            else:
                params.append(f"v_{param.name}={self._expr(param.default)}")
        prefix = "t_" if function.kind == "thread" else "f_"
        self._emit(0, f"def {prefix}{function.name}({', '.join(params)}):", function)
        for name, value in fresh:
            self._emit(1, f"if v_{name} is _D: v_{name} = {value}", function)
        self._globals(1, self.scope.body)
        self._block(1, self.scope.body)
        if function.kind == "thread" or function.name in self.checker.blocking:
            self._emit(1, "return", None)
            self._emit(1, "yield", None)

    def _block(self, indent: int, body: tuple[Any, ...]) -> None:
        emitted = False
        for statement in body:
            if not isinstance(statement, ast.Function):
                self._statement(indent, statement)
                emitted = True
        if not emitted:
            self._emit(indent, "pass", None)

    def _statement(self, indent: int, node: Any) -> None:
        io = self.checker.io_variable(self.scope, node.target) if isinstance(node, ast.Assign) else None
        if io is not None:
            writer = IO_VARIABLES[io][1]
            assert writer is not None  # the checker refuses assigning a read-only one
            self.used_io.add(writer)
            index = self._expr(node.target.indices[0])
            self._emit(indent, f"b_{writer}({index}, {self._expr(node.value)})", node)
        elif isinstance(node, ast.Assign):
            self._emit(
                indent, f"{self._target(node.target)} = {self._assigned(node.target, node.value)}", node
            )
        elif isinstance(node, ast.Declare):
            if node.value is not None:
                target = ast.Name(node.name, line=node.line, column=node.column)
                self._emit(indent, f"v_{node.name} = {self._assigned(target, node.value)}", node)
        elif isinstance(node, ast.ExprStatement):
            self._emit(indent, self._expr(node.value), node)
        elif isinstance(node, ast.If):
            self._if(indent, node)
        elif isinstance(node, ast.While):
            self._while(indent, node)
        elif isinstance(node, ast.Return):
            self._return(indent, node)
        elif isinstance(node, ast.Break):
            self._emit(indent, "break", node)
        elif isinstance(node, ast.Continue):
            self._emit(indent, "continue", node)
        elif isinstance(node, ast.Halt):
            self._emit(indent, "_halt()", node)
        elif isinstance(node, ast.EnterCritical):
            self._emit(indent, "pass  # enter_critical: a thread is never interrupted between blocks", node)
        elif isinstance(node, ast.ExitCritical):
            self._emit(indent, "pass  # exit_critical", node)
        elif isinstance(node, ast.Kill):
            self._emit(indent, f"_kill({self._expr(node.handle)})", node)
        elif isinstance(node, ast.Join):
            self._emit(indent, f"yield from _join({self._expr(node.handle)})", node)
        else:  # pragma: no cover - the parser makes no other statement
            raise TypeError(f"unknown statement {node!r}")

    def _if(self, indent: int, node: Any) -> None:
        """An ``if``/``elif``/``else`` chain."""
        for number, (condition, block) in enumerate(node.branches):
            keyword = "if" if number == 0 else "elif"
            self._emit(indent, f"{keyword} {self._expr(condition)}:", condition)
            self._block(indent + 1, block)
        if node.orelse is not None:
            self._emit(indent, "else:", None)
            self._block(indent + 1, node.orelse)

    def _while(self, indent: int, node: Any) -> None:
        """A ``while`` loop that gives up its time slice once the cycle's time is spent."""
        self._emit(indent, f"while {self._expr(node.condition)}:", node)
        if self.checker.body_blocks((node,)):
            # a loop that waits on something (a socket read that keeps finding data, say) has used
            # its time slice: the thread sleeps until the next cycle, as the controller's does
            self._emit(indent + 1, f"if {_SPENT}: yield", node)
        else:
            # a loop that can never wait would hold the controller: the controller's error
            self._emit(indent + 1, f"if {_SPENT}: _too_long()", node)
        self._block(indent + 1, node.body)

    def _return(self, indent: int, node: Any) -> None:
        """A ``return``; a copy of a list another variable holds when either side mutates it."""
        value = node.value
        if value is None:
            self._emit(indent, "return", node)
            return
        text = self._expr(value)
        if _is_read(value) and self.checker.mutated:
            text = f"_cp({text})"
        self._emit(indent, f"return {text}", node)

    def _assigned(self, target: Any, value: Any) -> str:
        """The value to store: a copy when it is another variable's list that either side mutates.

        A builtin's result stored in a variable the program mutates is copied too: a builtin may return a
        list it keeps (the arm's joint positions), which the program must not change behind its back.
        """
        text = self._expr(value)
        mutated = self.checker.mutated
        from_builtin = isinstance(value, ast.Call) and value.name not in self.checker.functions
        if from_builtin and target_root(target) in mutated:
            return f"_cp({text})"
        if not _is_read(value) or self._is_pose(value):
            return text
        if not isinstance(target, ast.Name) or target.name in mutated or target_root(value) in mutated:
            return f"_cp({text})"
        return text

    def _target(self, target: Any) -> str:
        if isinstance(target, ast.Name):
            return f"v_{target.name}"
        if isinstance(target, ast.Index):
            return self._target(target.base) + "".join(f"[{self._expr(i)}]" for i in target.indices)
        return self._attribute(self._target(target.base), target.name)

    @staticmethod
    def _attribute(base: str, name: str) -> str:
        return (
            f"{base}.{name}"
            if name.isidentifier() and not keyword.iskeyword(name)
            else f"{base}.__dict__[{name!r}]"
        )

    def _is_pose(self, node: Any) -> bool:
        return isinstance(node, ast.Index) and self.checker.is_pose(self.scope, node)

    def _expr(self, node: Any) -> str:
        if isinstance(node, ast.Number):
            return repr(node.value)
        if isinstance(node, ast.String):
            return repr(node.value)
        if isinstance(node, ast.Bool):
            return "True" if node.value else "False"
        if isinstance(node, ast.Name):
            if not self.checker.is_variable(self.scope, node.name):
                return repr(CONSTANTS[node.name])
            return f"v_{node.name}"
        if isinstance(node, ast.ListLiteral):
            return "_L([" + ", ".join(self._element(i) for i in node.items) + "])"
        if isinstance(node, ast.Index):
            if self._is_pose(node):
                return "_P([" + ", ".join(self._float(i) for i in node.indices) + "])"
            io = self.checker.io_variable(self.scope, node)
            if io is not None:
                reader = IO_VARIABLES[io][0]
                self.used_io.add(reader)
                return f"b_{reader}({self._expr(node.indices[0])})"
            return self._expr(node.base) + "".join(f"[{self._expr(i)}]" for i in node.indices)
        if isinstance(node, ast.Attribute):
            return self._attribute(self._expr(node.base), node.name)
        if isinstance(node, ast.Call):
            return self._call(node)
        if isinstance(node, ast.Run):
            return f"_start(t_{node.name})"
        if isinstance(node, ast.Unary):
            op = "not " if node.op == "not" else node.op
            return f"({op}{self._expr(node.operand)})"
        if isinstance(node, ast.Binary):
            left, right = self._expr(node.left), self._expr(node.right)
            if node.op == "xor":
                return f"(_b({left}) != _b({right}))"
            return f"({left} {node.op} {right})"
        raise TypeError(f"unknown expression {node!r}")  # pragma: no cover

    def _element(self, node: Any) -> str:
        text = self._expr(node)
        if _is_read(node) and not self._is_pose(node) and target_root(node) in self.checker.mutated:
            return f"_cp({text})"
        return text

    def _float(self, node: Any) -> str:
        if isinstance(node, ast.Number):
            return repr(float(node.value))
        return f"_f({self._expr(node)})"

    def _call(self, call: ast.Call) -> str:
        checker = self.checker
        function = checker.functions.get(call.name)
        if function is not None:
            bound = checker.bind_arguments(call, [(p.name, p.default is not None) for p in function.params])
            assert bound is not None
            parts = []
            for param, value in zip(function.params, bound, strict=True):
                if value is None:
                    continue
                text = self._expr(value)
                aliased = param.name in checker.mutated or target_root(value) in checker.mutated
                if aliased and _is_read(value) and not self._is_pose(value):
                    text = f"_cp({text})"
                parts.append(f"v_{param.name}={text}")
            text = f"f_{call.name}({', '.join(parts)})"
            return f"(yield from {text})" if call.name in checker.blocking else text
        if call.name == "struct":
            fields = ", ".join(f"({k.name!r}, {self._element(k.value)})" for k in call.keywords)
            return f"_S(({fields}{',' if len(call.keywords) == 1 else ''}))"
        signature = checker.signatures[call.name]
        bound = checker.bind_arguments(call, [(p.name, not p.required) for p in signature.params])
        assert bound is not None
        self.used.add(call.name)
        args = [
            self._default(p.default) if value is None else self._element(value)
            for p, value in zip(signature.params, bound, strict=True)
        ]
        text = f"b_{call.name}({', '.join(args)})"
        return f"(yield from {text})" if checker.builtin_blocks(call.name) else text

    def _default(self, value: object) -> str:
        if isinstance(value, (bool, int, float, str)) and type(value) in (bool, int, float, str):
            return repr(value)
        for name, known in self.constants.items():
            if known is value:
                return name
        name = f"_k{len(self.constants)}"
        self.constants[name] = value
        return name
