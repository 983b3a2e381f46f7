"""What a controller checks in a URScript program before it starts, and the names it resolves there.

:class:`Checker` (used by fakeur/urscript/compiler.py) resolves each function's names (its locals; every
other name read is a global), finds which functions may block and which variables the program mutates in
place, and refuses the whole program (:class:`ScriptCompileError` with line and column) for an unknown
function or variable, a wrong argument count, an unknown keyword argument, a socket name no
``socket_open`` of the program opens, a builtin this series/version does not have, a physical builtin in
a ``sec`` program, and the like. Code generation (fakeur/urscript/codegen.py) works from what it found.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Final

import urdaemon.fakeur.urscript.syntax as ast
from urdaemon.fakeur.urscript.lib_io import IO_DIGITAL_IN_GET, IO_DIGITAL_OUT_GET, IO_DIGITAL_OUT_SET
from urdaemon.fakeur.urscript.runtime import Builtin, ScriptCompileError

__all__ = [
    "CONSTANTS",
    "DEFAULT_SOCKET",
    "IO_VARIABLES",
    "Checker",
    "Scope",
    "statement_expressions",
    "target_root",
    "walk_expressions",
    "walk_statements",
]

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
"""The socket a socket builtin uses when the program names none."""


# -- walking the syntax tree ------------------------------------------------------------------------


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


class Checker:
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
