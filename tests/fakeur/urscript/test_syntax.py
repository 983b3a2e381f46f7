"""The URScript grammar: every construct, operator precedence, and syntax errors with line and column."""

from __future__ import annotations

import pytest

from urdaemon.fakeur.urscript import ScriptCompileError
from urdaemon.fakeur.urscript import syntax as ast
from urdaemon.fakeur.urscript.syntax import parse


def _expr(text: str) -> ast.Expr:
    (statement,) = parse(f"x = {text}")
    assert isinstance(statement, ast.Assign)
    return statement.value


def _shape(node: object) -> object:
    """A compact nested form of an expression to compare precedence with."""
    if isinstance(node, ast.Binary):
        return (node.op, _shape(node.left), _shape(node.right))
    if isinstance(node, ast.Unary):
        return (node.op, _shape(node.operand))
    if isinstance(node, ast.Name):
        return node.name
    if isinstance(node, ast.Number):
        return node.value
    if isinstance(node, ast.Index):
        return ("[]", _shape(node.base), *map(_shape, node.indices))
    if isinstance(node, ast.Attribute):
        return (".", _shape(node.base), node.name)
    if isinstance(node, ast.Call):
        return ("call", node.name, *map(_shape, node.args))
    raise AssertionError(node)


@pytest.mark.parametrize(
    ("text", "shape"),
    [
        ("a or b and c", ("or", "a", ("and", "b", "c"))),
        ("a and b or c", ("or", ("and", "a", "b"), "c")),
        ("a xor b and c", ("xor", "a", ("and", "b", "c"))),
        ("a or b xor c", ("xor", ("or", "a", "b"), "c")),
        ("not a == b", ("not", ("==", "a", "b"))),
        ("not a and b", ("and", ("not", "a"), "b")),
        ("a == b + c", ("==", "a", ("+", "b", "c"))),
        ("a < b == c", None),  # comparisons do not chain: a syntax error
        ("a + b * c", ("+", "a", ("*", "b", "c"))),
        ("a - b - c", ("-", ("-", "a", "b"), "c")),
        ("a / b * c", ("*", ("/", "a", "b"), "c")),
        ("a % b + c", ("+", ("%", "a", "b"), "c")),
        ("-a * b", ("*", ("-", "a"), "b")),
        ("-a[1].y", ("-", (".", ("[]", "a", 1), "y"))),
        ("-2 * b", ("*", -2, "b")),
        ("(a + b) * c", ("*", ("+", "a", "b"), "c")),
        ("f(a, b)[0] + 1", ("+", ("[]", ("call", "f", "a", "b"), 0), 1)),
        ("a <= b and c != d", ("and", ("<=", "a", "b"), ("!=", "c", "d"))),
    ],
)
def test_operator_precedence(text: str, shape: object) -> None:
    if shape is None:
        with pytest.raises(ScriptCompileError):
            _expr(text)
        return
    assert _shape(_expr(text)) == shape


def test_literals() -> None:
    assert _expr("12") == ast.Number(12, line=1, column=5)
    small = _expr("1.5e-3")
    assert isinstance(small, ast.Number)
    assert small.value == pytest.approx(1.5e-3)
    assert _expr(".5") == ast.Number(0.5, line=1, column=5)
    assert _expr('"a # not a comment"') == ast.String("a # not a comment", line=1, column=5)
    assert _expr("True") == ast.Bool(True, line=1, column=5)
    assert _expr("False") == ast.Bool(False, line=1, column=5)
    listed = _expr("[1, [2, 3], []]")
    assert isinstance(listed, ast.ListLiteral)
    assert len(listed.items) == 3
    pose = _expr("p[0, 0.1, -2, 0, 0, 3.14]")
    assert isinstance(pose, ast.Index)
    assert isinstance(pose.base, ast.Name)
    assert len(pose.indices) == 6
    struct = _expr("struct(a=1, b=[1, 2])")
    assert isinstance(struct, ast.Call)
    assert [k.name for k in struct.keywords] == ["a", "b"]


def test_every_statement_kind() -> None:
    text = """
def prog():
  global g = 1
  local l = 2
  l = g
  l[0] = 1
  s.f = 2
  m[1, 2] = 3
  if a:
    b()
  elif c:
    d()
  elif e:
    f()
  else:
    halt
  end
  while True:
    break
    continue
  end
  h = run worker()
  run worker()
  kill h
  join h
  enter_critical
  exit_critical
  return 5
  return
end
thread worker():
  sync()
end
sec guard():
  textmsg("x")
end
"""
    prog, worker, guard = parse(text)
    assert isinstance(prog, ast.Function)
    assert prog.kind == "def"
    assert prog.name == "prog"
    assert [type(s).__name__ for s in prog.body] == [
        "Declare",
        "Declare",
        "Assign",
        "Assign",
        "Assign",
        "Assign",
        "If",
        "While",
        "Assign",
        "ExprStatement",
        "Kill",
        "Join",
        "EnterCritical",
        "ExitCritical",
        "Return",
        "Return",
    ]
    branches = prog.body[6]
    assert isinstance(branches, ast.If)
    assert len(branches.branches) == 3
    assert branches.orelse is not None
    loop = prog.body[7]
    assert isinstance(loop, ast.While)
    assert [type(s) for s in loop.body] == [ast.Break, ast.Continue]
    assert isinstance(worker, ast.Function)
    assert worker.kind == "thread"
    assert isinstance(guard, ast.Function)
    assert guard.kind == "sec"


def test_parameters_with_defaults_and_keyword_arguments() -> None:
    (function,) = parse("def f(a, b=2):\n  g(a, x=b)\nend")
    assert isinstance(function, ast.Function)
    assert [(p.name, p.default) for p in function.params] == [
        ("a", None),
        ("b", ast.Number(2, line=1, column=12)),
    ]
    (call,) = function.body
    assert isinstance(call, ast.ExprStatement)
    assert isinstance(call.value, ast.Call)
    assert [k.name for k in call.value.keywords] == ["x"]


def test_newlines_are_whitespace() -> None:
    """ur_rtde's script splits `global a = 0` over lines with a comment between (works on real robots)."""
    items = parse("global a = # float register offset\n0    global b = 1 x = a +\n b if x: y = 1 end")
    assert [type(i).__name__ for i in items] == ["Declare", "Declare", "Assign", "If"]
    first = items[0]
    assert isinstance(first, ast.Declare)
    assert first.value == ast.Number(0, line=2, column=1)


def test_labels_comments_and_positions() -> None:
    text = '$ 1 "BeforeStart"\n# a comment\n  $ 2 "Robot Program" "breakAfter"\n\tx = 1 # trailing\n'
    (assign,) = parse(text)
    assert isinstance(assign, ast.Assign)
    assert (assign.line, assign.column) == (4, 2)
    assert (assign.value.line, assign.value.column) == (4, 6)


@pytest.mark.parametrize(
    ("text", "line", "column"),
    [
        ("def f():\n  x = 1\n", 1, 1),  # missing end: the block left open
        ("while a:\n  if b:\n    c = 1\n  elif d:\n    e = 1\nend\n", 1, 1),
        ("x = 1\nthread t():\n  while True:\n    sync()\n  end\n", 2, 1),
        ("x = 1\ny = = 2\n", 2, 5),
        ("if x\n  y = 1\nend\n", 2, 3),  # missing colon
        ("x = (1 + 2\n", 2, 1),
        ("x = 1\n  end\n", 2, 3),
        ("def f(:\nend", 1, 7),
        ("x = 'open\n", 1, 5),
    ],
)
def test_syntax_error_names_line_and_column(text: str, line: int, column: int) -> None:
    with pytest.raises(ScriptCompileError) as caught:
        parse(text)
    assert (caught.value.line, caught.value.column) == (line, column)
    assert "syntax_error" in caught.value.message


def test_a_missing_end_names_the_block_it_leaves_open() -> None:
    with pytest.raises(ScriptCompileError) as caught:
        parse("def f():\n  while x:\n    if y:\n      z = 1\n    end\n")
    assert caught.value.message == "syntax_error_on_line:2: while block has no end"
    assert (caught.value.line, caught.value.column) == (2, 3)


@pytest.mark.parametrize(
    ("text", "line", "column"),
    [
        ("x = 1\ny = \u00e9\n", 2, 5),
        ("# caf\u00e9\nx = 1", 1, 6),
        ('textmsg("\u2013")', 1, 10),
        ('$ 3 "a\u2254b" x = \u00e9\n', 1, 15),  # a label's text only, not what follows on its line
        ('x = "$ 3 \u2254"\n', 1, 10),
    ],
)
def test_non_ascii_is_refused_with_its_position(text: str, line: int, column: int) -> None:
    with pytest.raises(ScriptCompileError) as caught:
        parse(text)
    assert (caught.value.line, caught.value.column) == (line, column)
    assert "non-ASCII" in caught.value.message


def test_step_labels_may_carry_the_pendants_symbols() -> None:
    """Reproduction: PolyScope writes a node's text as the pendant shows it into its step labels
    (UR's URScript_Examples, execution-time/timing_debug.script: ``$ 3 "var_4≔4"``,
    ``$ 22 "If var_3≟0"``) and a controller runs the script; the fake refused any non-ASCII
    character, so a script PolyScope generated was refused at 2:13."""
    text = (
        "def timing():\n"
        '  $ 3 "var_4\u22544"\n'
        "  global var_4=4\n"
        "  while (True):\n"
        '    $ 22 "If var_4\u225f0"\n'
        "    if (var_4 == 0):\n"
        '      $ 15 "Waypoint_1" "breakAfter"\n'
        "      sync()\n"
        "    end\n"
        "    sync()\n"
        "  end\n"
        "end\n"
    )
    (function,) = parse(text)
    assert isinstance(function, ast.Function)
    assert [type(s).__name__ for s in function.body] == ["Declare", "While"]


@pytest.mark.parametrize(
    ("text", "line", "column"),
    [
        ('# $ 1 "\u00e9"\n', 1, 8),  # a comment that looks like a label is a comment
        ('x = 1 $ 1 "\u00e9"\n', 1, 12),  # a label is a line of its own
        ('x = 1\ny = 2 # $ 2 "\u2254"\n', 2, 14),
    ],
)
def test_a_label_only_starts_a_line(text: str, line: int, column: int) -> None:
    """Reproduction: the ASCII check found labels anywhere (``_STEP_LABEL``, unanchored), so the
    comment ``# $ 1 "é"`` let ``é`` through and the script compiled; its pattern (``+``) also
    differed from the grammar's ``LABEL`` (``*``)."""
    with pytest.raises(ScriptCompileError) as caught:
        parse(text)
    assert (caught.value.line, caught.value.column) == (line, column)
    assert "non-ASCII" in caught.value.message


@pytest.mark.parametrize(
    "text",
    [
        '$ 1 "BeforeStart"',
        '  $ 2 "Robot Program" "breakAfter"',
        "\t$ 3",
        '$4 "var_4\u22544"',
        '    $ 22 "If var_3\u225f0"',
    ],
)
def test_the_ascii_check_and_the_grammar_share_one_label(text: str) -> None:
    """One definition: the ASCII check's pattern is the grammar's ``LABEL`` terminal, and a line the
    check takes for a label is one the parser skips (before the fix they were two patterns)."""
    assert ast.step_label().pattern == ast._parser().get_terminal("LABEL").pattern.to_regexp()
    script = f"x = 1\n{text}\ny = 2\n"
    (match,) = ast.step_label().finditer(script)
    assert match.group() == text
    first, second = parse(script)
    assert isinstance(first, ast.Assign)
    assert isinstance(second, ast.Assign)
    assert (second.line, second.column) == (3, 1)


@pytest.mark.parametrize("text", ['x = 1 $ 1 "a"\n', "f() $ 2\n", '# c\nx = 1 \t$ 3 "b"\n'])
def test_a_label_after_a_statement_is_a_syntax_error(text: str) -> None:
    """The grammar's label also starts a line only: mid-line, ``$`` is no token of URScript."""
    with pytest.raises(ScriptCompileError) as caught:
        parse(text)
    assert "syntax_error" in caught.value.message
