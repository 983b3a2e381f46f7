"""URScript text -> AST: frozen dataclasses carrying the 1-based ``line`` and ``column`` of what they are.

The grammar is ``grammar.lark`` (lark, LALR). Syntax errors and non-ASCII characters (outside the
text of PolyScope's ``$ n "label"`` lines) raise
:class:`~urdaemon.fakeur.urscript.runtime.ScriptCompileError` naming the line and column, the way the
controller refuses a program before it starts.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, TypeAlias

import lark
from lark import Token, Transformer

from urdaemon.fakeur.urscript.runtime import ScriptCompileError

__all__ = [
    "Assign",
    "Attribute",
    "Binary",
    "Bool",
    "Break",
    "Call",
    "Continue",
    "Declare",
    "EnterCritical",
    "ExitCritical",
    "Expr",
    "ExprStatement",
    "Function",
    "Halt",
    "If",
    "Index",
    "Join",
    "Keyword",
    "Kill",
    "ListLiteral",
    "Name",
    "Node",
    "Number",
    "Param",
    "Return",
    "Run",
    "Statement",
    "String",
    "Unary",
    "While",
    "parse",
    "step_label",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class Node:
    line: int = field(compare=False)
    column: int = field(compare=False)


# -- expressions ----------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Number(Node):
    value: int | float


@dataclass(frozen=True, slots=True)
class String(Node):
    value: str


@dataclass(frozen=True, slots=True)
class Bool(Node):
    value: bool


@dataclass(frozen=True, slots=True)
class Name(Node):
    name: str


@dataclass(frozen=True, slots=True)
class ListLiteral(Node):
    items: tuple[Expr, ...]


@dataclass(frozen=True, slots=True)
class Index(Node):
    """``base[i]`` (or ``base[i, j]``; ``p[x, y, z, rx, ry, rz]`` is a pose when ``p`` is no variable)."""

    base: Expr
    indices: tuple[Expr, ...]


@dataclass(frozen=True, slots=True)
class Attribute(Node):
    base: Expr
    name: str


@dataclass(frozen=True, slots=True)
class Keyword(Node):
    name: str
    value: Expr


@dataclass(frozen=True, slots=True)
class Call(Node):
    name: str
    args: tuple[Expr, ...]
    keywords: tuple[Keyword, ...]


@dataclass(frozen=True, slots=True)
class Run(Node):
    """``run thread_name()``: starts a thread, its value is the thread's handle."""

    name: str


@dataclass(frozen=True, slots=True)
class Unary(Node):
    op: str  # "-", "+" or "not"
    operand: Expr


@dataclass(frozen=True, slots=True)
class Binary(Node):
    op: str  # "or" "xor" "and" "==" "!=" "<" ">" "<=" ">=" "+" "-" "*" "/" "%"
    left: Expr
    right: Expr


Expr: TypeAlias = (
    Number | String | Bool | Name | ListLiteral | Index | Attribute | Call | Run | Unary | Binary
)

# -- statements -----------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Assign(Node):
    target: Name | Index | Attribute
    value: Expr


@dataclass(frozen=True, slots=True)
class Declare(Node):
    scope: str  # "global" or "local"
    name: str
    value: Expr | None


@dataclass(frozen=True, slots=True)
class ExprStatement(Node):
    value: Call | Run


@dataclass(frozen=True, slots=True)
class If(Node):
    branches: tuple[tuple[Expr, tuple[Statement, ...]], ...]
    orelse: tuple[Statement, ...] | None


@dataclass(frozen=True, slots=True)
class While(Node):
    condition: Expr
    body: tuple[Statement, ...]


@dataclass(frozen=True, slots=True)
class Return(Node):
    value: Expr | None


@dataclass(frozen=True, slots=True)
class Break(Node):
    pass


@dataclass(frozen=True, slots=True)
class Continue(Node):
    pass


@dataclass(frozen=True, slots=True)
class Halt(Node):
    pass


@dataclass(frozen=True, slots=True)
class EnterCritical(Node):
    pass


@dataclass(frozen=True, slots=True)
class ExitCritical(Node):
    pass


@dataclass(frozen=True, slots=True)
class Kill(Node):
    handle: Expr


@dataclass(frozen=True, slots=True)
class Join(Node):
    handle: Expr


@dataclass(frozen=True, slots=True)
class Param(Node):
    name: str
    default: Expr | None


@dataclass(frozen=True, slots=True)
class Function(Node):
    """``def``, ``sec`` or ``thread`` (kind); its body may hold nested definitions."""

    kind: str
    name: str
    params: tuple[Param, ...]
    body: tuple[Statement, ...]


Statement: TypeAlias = (
    Assign
    | Declare
    | ExprStatement
    | If
    | While
    | Return
    | Break
    | Continue
    | Halt
    | EnterCritical
    | ExitCritical
    | Kill
    | Join
    | Function
)

# -- parsing --------------------------------------------------------------------------------------------


@cache
def _parser() -> lark.Lark:
    """The LALR parser; the AST is built while parsing (no parse tree), positions come from tokens."""
    grammar = (Path(__file__).parent / "grammar.lark").read_text(encoding="ascii")
    return lark.Lark(grammar, parser="lalr", maybe_placeholders=True, transformer=_Build())


def _at(node: Any) -> dict[str, int]:
    """The position of a token or of an AST node."""
    if isinstance(node, Token):
        return {"line": node.line or 0, "column": node.column or 0}
    return {"line": node.line, "column": node.column}


def _number(text: str) -> int | float:
    if any(c in text for c in ".eE"):
        return float(text)
    return int(text)


def _no_brackets(children: list[Any]) -> list[Any]:
    return [c for c in children if not (isinstance(c, Token) and c.type == "LSQB")]


class _Build(Transformer[Token, Any]):
    """Grammar rules -> AST nodes, called by the parser as it reduces (one pass, no tree)."""

    def start(self, children: list[Any]) -> tuple[Any, ...]:
        return tuple(children)

    def function(self, children: list[Any]) -> Function:
        kind, name, *rest = children
        params = tuple(c for c in rest if isinstance(c, Param))
        body = tuple(c for c in rest if c is not None and not isinstance(c, Param))
        return Function(str(kind), str(name), params, body, **_at(kind))

    def thread(self, children: list[Any]) -> Function:
        keyword, name, *body = children
        return Function("thread", str(name), (), tuple(body), **_at(keyword))

    def param(self, children: list[Any]) -> Param:
        return Param(str(children[0]), children[1], **_at(children[0]))

    def assign(self, children: list[Any]) -> Assign:
        return Assign(children[0], children[1], **_at(children[0]))

    def declare(self, children: list[Any]) -> Declare:
        return Declare(str(children[0]), str(children[1]), children[2], **_at(children[0]))

    def call_statement(self, children: list[Any]) -> ExprStatement:
        return ExprStatement(children[0], **_at(children[0]))

    def run_statement(self, children: list[Any]) -> ExprStatement:
        return ExprStatement(children[0], **_at(children[0]))

    def return_statement(self, children: list[Any]) -> Return:
        return Return(children[1], **_at(children[0]))

    def break_statement(self, children: list[Any]) -> Break:
        return Break(**_at(children[0]))

    def continue_statement(self, children: list[Any]) -> Continue:
        return Continue(**_at(children[0]))

    def halt_statement(self, children: list[Any]) -> Halt:
        return Halt(**_at(children[0]))

    def enter_critical(self, children: list[Any]) -> EnterCritical:
        return EnterCritical(**_at(children[0]))

    def exit_critical(self, children: list[Any]) -> ExitCritical:
        return ExitCritical(**_at(children[0]))

    def kill_statement(self, children: list[Any]) -> Kill:
        return Kill(children[1], **_at(children[0]))

    def join_statement(self, children: list[Any]) -> Join:
        return Join(children[1], **_at(children[0]))

    def target(self, children: list[Any]) -> Name:
        return Name(str(children[0]), **_at(children[0]))

    def target_index(self, children: list[Any]) -> Index:
        base, *indices = _no_brackets(children)
        return Index(base, tuple(indices), **_at(base))

    def target_attr(self, children: list[Any]) -> Attribute:
        return Attribute(children[0], str(children[1]), **_at(children[0]))

    def if_statement(self, children: list[Any]) -> If:
        keyword, condition, *rest = children
        orelse = rest.pop() if rest and (rest[-1] is None or isinstance(rest[-1], _Else)) else None
        elifs = [c for c in rest if isinstance(c, _Elif)]
        body = tuple(c for c in rest if not isinstance(c, _Elif))
        branches = ((condition, body), *((e.condition, e.body) for e in elifs))
        return If(branches, orelse.body if isinstance(orelse, _Else) else None, **_at(keyword))

    def elif_clause(self, children: list[Any]) -> _Elif:
        return _Elif(children[0], tuple(children[1:]))

    def else_clause(self, children: list[Any]) -> _Else:
        return _Else(tuple(children))

    def while_statement(self, children: list[Any]) -> While:
        return While(children[1], tuple(children[2:]), **_at(children[0]))

    def binary(self, children: list[Any]) -> Binary:
        left, op, right = children
        return Binary(str(op), left, right, **_at(left))

    def unary(self, children: list[Any]) -> Expr:
        op, operand = children
        if str(op) == "-" and isinstance(operand, Number):
            return Number(-operand.value, **_at(op))
        return Unary(str(op), operand, **_at(op))

    def index(self, children: list[Any]) -> Index:
        base, *indices = _no_brackets(children)
        return Index(base, tuple(indices), **_at(base))

    def attribute(self, children: list[Any]) -> Attribute:
        return Attribute(children[0], str(children[1]), **_at(children[0]))

    def number(self, children: list[Any]) -> Number:
        return Number(_number(str(children[0])), **_at(children[0]))

    def string(self, children: list[Any]) -> String:
        return String(str(children[0])[1:-1], **_at(children[0]))

    def true(self, children: list[Any]) -> Bool:
        return Bool(True, **_at(children[0]))

    def false(self, children: list[Any]) -> Bool:
        return Bool(False, **_at(children[0]))

    def name(self, children: list[Any]) -> Name:
        return Name(str(children[0]), **_at(children[0]))

    def list_literal(self, children: list[Any]) -> ListLiteral:
        bracket, *items = children
        return ListLiteral(tuple(c for c in items if c is not None), **_at(bracket))

    def run_expr(self, children: list[Any]) -> Run:
        return Run(str(children[1]), **_at(children[0]))

    def call(self, children: list[Any]) -> Call:
        name, *arguments = children
        args = tuple(a for a in arguments if a is not None and not isinstance(a, Keyword))
        keywords = tuple(a for a in arguments if isinstance(a, Keyword))
        return Call(str(name), args, keywords, **_at(name))

    def argument(self, children: list[Any]) -> Any:
        return children[0]

    def keyword_argument(self, children: list[Any]) -> Keyword:
        return Keyword(str(children[0]), children[1], **_at(children[0]))


@dataclass(frozen=True, slots=True)
class _Elif:
    condition: Expr
    body: tuple[Statement, ...]


@dataclass(frozen=True, slots=True)
class _Else:
    body: tuple[Statement, ...]


@cache
def step_label() -> re.Pattern[str]:
    """A step label: the grammar's ``LABEL`` terminal, the one definition of it (a line of its own,
    ``$ 3 "var_4≔4"``). PolyScope writes the node's text there as the pendant shows it (``$ 22 "If
    var_3≟0"``), and a controller runs such scripts."""
    return re.compile(_parser().get_terminal("LABEL").pattern.to_regexp())


def _check_ascii(text: str) -> None:
    """Refuse a non-ASCII character anywhere but in a step label's text."""
    if text.isascii():
        return
    labels = [match.span() for match in step_label().finditer(text)]
    for offset, char in enumerate(text):
        if ord(char) <= 127 or any(start < offset < end for start, end in labels):
            continue
        start = text.rfind("\n", 0, offset) + 1
        raise ScriptCompileError(
            text.count("\n", 0, offset) + 1,
            offset - start + 1,
            f"syntax_error: non-ASCII character {char!r} (U+{ord(char):04X})",
        )


def _source_line(text: str, line: int) -> str:
    lines = text.splitlines()
    return lines[line - 1] if 0 < line <= len(lines) else ""


_BLOCK_OPENERS = frozenset({"DEF", "SEC", "THREAD", "IF", "WHILE"})


def _unclosed_block(error: lark.UnexpectedInput) -> Token | None:
    """The keyword of the innermost block still open when the program ended, if the parser knows it."""
    interactive = getattr(error, "interactive_parser", None)
    if interactive is None:
        return None
    for value in reversed(interactive.parser_state.value_stack):
        if isinstance(value, Token) and value.type in _BLOCK_OPENERS:
            return value
    return None


def parse(text: str) -> tuple[Function | Statement, ...]:
    """Top-level items of ``text``: definitions and statements, in order."""
    _check_ascii(text)
    try:
        tree = _parser().parse(text)
    except lark.UnexpectedInput as error:
        at_end = isinstance(error, lark.UnexpectedEOF) or (
            isinstance(error, lark.UnexpectedToken) and error.token.type == "$END"
        )
        if at_end or error.line < 1:
            line = text.count("\n") + 1
            column = len(text) - (text.rfind("\n") + 1) + 1
            message = "syntax_error_on_line: unexpected end of program"
            opener = _unclosed_block(error)
            if opener is not None:  # point at the block a missing `end` leaves open
                line, column = opener.line or line, opener.column or column
                message = f"syntax_error_on_line:{line}: {opener.value} block has no end"
        else:
            line, column = error.line, error.column
            message = f"syntax_error_on_line:{line}:{_source_line(text, line)}:"
        raise ScriptCompileError(line, column, message) from None
    items: tuple[Function | Statement, ...] = tree  # type: ignore[assignment] # the transformer's start
    return items
