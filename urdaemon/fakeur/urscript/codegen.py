"""A checked URScript program as Python source: :class:`CodeGenerator`.

Every URScript function and thread becomes one Python function of a generated module, one statement per
line with a table back to the URScript line and column (fakeur/urscript/compiler.py compiles it once
per program text): those that may block are generators called with ``yield from``; the others stay
plain functions. Names are prefixed (``v_`` variables, ``f_`` functions, ``t_`` threads, ``b_`` builtins)
so no URScript name can clash with Python's. It works from what the checks found
(fakeur/urscript/checker.py): the scopes, the functions that block, the variables mutated in place.
A loop that may be put aside (in the main program, a thread, or a function that blocks: a generator)
gives up the rest of its thread's cycle once its time slice is used; one that cannot (in a function
that never blocks) stops the program with the controller's error once it runs too long in one cycle.
"""

from __future__ import annotations

import keyword
from typing import Any, Final

import urdaemon.fakeur.urscript.syntax as ast
from urdaemon.fakeur.urscript.checker import CONSTANTS, IO_VARIABLES, Checker, target_root, walk_statements

__all__ = ["MAX_OPS_PER_CYCLE", "CodeGenerator"]

MAX_OPS_PER_CYCLE: Final = 100_000
"""Loop iterations a loop that cannot be put aside (in a function that never blocks) may run in one
controller cycle before the program stops with the controller's error (or sooner:
``runtime.STALL_BUDGET_S`` of processor time)."""

_SLICE_USED: Final = "_pc() > _end"
"""A loop's test, each iteration, of whether its thread has used its time slice of this cycle (inline:
it is hot; ``_end`` is the slice's end, set by the scheduler as it resumes the thread)."""
_TOO_LONG: Final = f"(_n := _next(_tick)) > {MAX_OPS_PER_CYCLE} or (_n & 255 == 0 and _stalled())"
"""The same test for a loop that cannot be put aside: whether it has run too long to go on."""

_INDENT: Final = "    "


def _is_read(node: Any) -> bool:
    """An expression whose value may be another variable's list or struct (not a fresh one)."""
    return isinstance(node, (ast.Name, ast.Index, ast.Attribute))


class CodeGenerator:
    """Python source for a checked program, one statement per line, with its line table."""

    def __init__(self, checker: Checker) -> None:
        self.checker = checker
        self.out: list[str] = []
        self.lines: dict[int, tuple[int, int]] = {}
        self.used: set[str] = set()
        self.used_io: set[str] = set()
        """Registry names of the IO variables' readers and writers the program uses."""
        self.constants: dict[str, object] = {}
        self.scope = checker.main
        self.loops = 0
        self.suspendable = True
        """The code being generated is a generator's (main, a thread, a blocking function): it may yield."""

    def generate(self) -> tuple[str, dict[int, tuple[int, int]], set[str], dict[str, object]]:
        for name, function in self.checker.functions.items():
            self.scope = self.checker.scopes[name]
            self.suspendable = function.kind == "thread" or name in self.checker.blocking
            self._function(function)
        self.scope = self.checker.main
        self.suspendable = True
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
        """A ``while`` loop that gives up its time slice once it is used."""
        if self.suspendable:
            # a thread that used its time slice (writing to a socket, reading one a client floods, or
            # computing) is put aside until the next cycle, as UR's scheduler does; it resumes here.
            # Only once the loop went round again since it found the slice used, in the same resume:
            # a loop that blocks every time round (a servoj stream) is never put aside before its
            # motion, however slow the fake's own work was before it (the fake is no real-time machine)
            self.loops += 1
            mark = f"_s{self.loops}"
            self._emit(indent, f"{mark} = -1", node)
            self._emit(indent, f"while {self._expr(node.condition)}:", node)
            self._emit(indent + 1, f"if {_SLICE_USED}:", node)
            self._emit(indent + 2, f"if {mark} == _r: yield", node)
            self._emit(indent + 2, f"else: {mark} = _r", node)
        else:
            # a plain function cannot be put aside: one that loops too long would hold the controller
            self._emit(indent, f"while {self._expr(node.condition)}:", node)
            self._emit(indent + 1, f"if {_TOO_LONG}: _too_long()", node)
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
