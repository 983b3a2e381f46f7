"""compile_program: each compile error kind with line and column, code generation, real scripts."""

from __future__ import annotations

import inspect
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from urdaemon.fakeur.urscript import ScriptCompileError, compile_program
from urdaemon.fakeur.urscript.runtime import Builtin, UrList
from urdaemon.fakeur.urscript.signatures import Param, Signature
from urdaemon.protocols.primary import headless_program
from urdaemon.urscript import ScriptParameters, render_control_script

RTDE_CONTROL_SCRIPT = Path("/tmp/scripts/rtde_control.script")


def _sig(name: str, *params: str | tuple[str, object], physical: bool = False) -> Signature:
    return Signature(
        name,
        tuple(Param(p) if isinstance(p, str) else Param(p[0], p[1]) for p in params),
        physical,
        {"e": (5, 0), "cb3": (3, 0)},
    )


STUB_TABLE: dict[str, Signature] = {
    s.name: s
    for s in (
        _sig("textmsg", "s1", ("s2", "")),
        _sig("sync", physical=True),
        _sig("sleep", "t", physical=True),
        _sig("movej", "q", ("a", 1.4), ("v", 1.05), ("t", 0), ("r", 0), physical=True),
        _sig("socket_open", "address", "port", ("socket_name", "socket_0")),
        _sig("socket_send_int", "value", ("socket_name", "socket_0")),
        _sig(
            "socket_read_binary_integer", "number", ("socket_name", "socket_0"), ("timeout", 2), physical=True
        ),
        _sig("boom", "message"),
        _sig("record", "value"),
        _sig("absent"),
        _sig("get_list", ("default", UrList([1, 2]))),
    )
}
"""A small table of our own (not functions.yaml) so these tests check the compiler alone."""


def compile_stub(text: str, **implementations: Builtin) -> Any:
    return compile_program(text, signatures=STUB_TABLE, builtins=implementations)


def _refused(text: str) -> ScriptCompileError:
    with pytest.raises(ScriptCompileError) as caught:
        compile_stub(text)
    return caught.value


@pytest.mark.parametrize(
    ("text", "line", "column", "words"),
    [
        ("x = 1\nservoj2(x)\n", 2, 1, "compile_error_name_not_found:servoj2:"),
        ("def f():\n  x = y + 1\nend\n", 2, 7, "compile_error_name_not_found:y:"),
        ("def f():\n  textmsg(x)\nend\nx = 1\nf()\n", None, None, None),  # a program variable: fine
        (
            "def f():\n  local a = 1\nend\ndef g():\n  return a\nend\n",
            5,
            10,
            "compile_error_name_not_found:a:",
        ),
        ("sleep(1, 2)\n", 1, 1, "wrong number of arguments for sleep"),
        ("x = 0\nsleep()\n", 2, 1, "missing t"),
        ("def f(a, b=1):\n  return a\nend\nf()\n", 4, 1, "missing a"),
        ("def f(a):\n  return a\nend\nf(1, 2)\n", 4, 1, "wrong number of arguments for f"),
        ("movej([0, 0, 0, 0, 0, 0], a=1, speed=2)\n", 1, 32, "unknown keyword argument speed for movej"),
        ("movej([0, 0, 0, 0, 0, 0], 1, a=1)\n", 1, 30, "argument a of movej given twice"),
        (
            'socket_open("1.2.3.4", 5, "reverse_socket")\nsocket_send_int(1, "revrse_socket")\n',
            2,
            20,
            'socket "revrse_socket" is not opened',
        ),
        ('socket_send_int(1, "socket_0")\nsocket_send_int(2)\n', None, None, None),  # the default socket
        ('socket_open("h", 1, socket_name="a")\nsocket_send_int(1, socket_name="a")\n', None, None, None),
        # a socket_open whose name is computed (urcl opens its sockets in a function): any name may be open
        (
            'def connect(name):\n  return socket_open("h", 1, name)\nend\n'
            'x = connect("b")\nsocket_send_int(1, "b")\n',
            None,
            None,
            None,
        ),
        ("x = p[1, 2, 3]\n", 1, 5, "a pose p[...] takes 6 numbers, not 3"),
        ("break\n", 1, 1, "break outside a loop"),
        ("g = 1\ndef f(a=g):\n  return a\nend\n", 2, 9, "default of parameter a must be a constant"),
        ("def f(a=[1, -2], b=p[0, 0, 0, 0, 0, 0], c=False):\n  return a\nend\nx = f()\n", None, None, None),
        ("thread t():\n  sync()\nend\nt()\n", 4, 1, "thread t is started with run"),
        ("def f():\n  return 1\nend\nh = run f()\n", 4, 5, "no such thread"),
        ("x[0] = 1\n", 1, 1, "compile_error_name_not_found:x:"),
        ("x = struct(1)\n", 1, 5, "struct() takes only named fields"),
    ],
)
def test_compile_errors_name_line_and_column(
    text: str, line: int | None, column: int | None, words: str
) -> None:
    if line is None:
        compile_stub(text)
        return
    error = _refused(text)
    assert words in error.message
    assert (error.line, error.column) == (line, column)


def test_the_first_error_in_the_text_is_reported() -> None:
    error = _refused("def f():\n  a = unknown_b\nend\nunknown_a()\n")
    assert (error.line, error.column, error.message) == (2, 7, "compile_error_name_not_found:unknown_b:")


def test_sec_program_may_not_call_a_physical_builtin() -> None:
    error = _refused('sec check():\n  textmsg("ok")\n  sleep(1)\nend\n')
    assert (error.line, error.column) == (3, 3)
    assert "sec program may not call" in error.message
    assert compile_stub('sec check():\n  textmsg("ok")\nend\n').kind == "sec"


def test_builtin_of_another_version_is_refused() -> None:
    """tool_wrench_limit_set exists from PolyScope 5.22 on (functions.yaml): a 5.12 controller refuses it."""
    text = "x = 0\ntool_wrench_limit_set(p[0, 0, 0, 0, 0, 0], 1, 1, 1, 1, 1, 1)\n"
    compile_program(text, series="e", version=(5, 22))
    with pytest.raises(ScriptCompileError) as caught:
        compile_program(text, series="e", version=(5, 12))
    assert (caught.value.line, caught.value.column) == (2, 1)
    assert "not available on this controller" in caught.value.message


def test_program_kinds() -> None:
    assert compile_stub("def main():\n  sync()\nend\n").kind == "def"
    assert compile_stub("sec s():\n  textmsg(1)\nend\n").kind == "sec"
    assert compile_stub("movej([0, 0, 0, 0, 0, 0], a=1, v=1)\n").kind == "line"
    assert compile_stub("def f():\n  sync()\nend\nf()\n").kind == "line"


def _functions(source: str) -> Iterator[str]:
    for line in source.splitlines():
        if line.startswith("def "):
            yield line


def test_functions_that_may_block_become_generators_the_others_stay_plain() -> None:
    text = """
def plain(a):
  return a + 1
end
def waits():
  sync()
end
def calls_waits():
  waits()
end
def joins(h):
  join h
end
def calls_plain():
  return plain(1)
end
calls_waits()
"""
    program = compile_stub(text, sync=Builtin("sync", _wait_once, blocking=True))
    namespace: dict[str, Any] = {}
    exec(program.code, {"__builtins__": {}}, namespace)
    generators = {name for name, f in namespace.items() if inspect.isgeneratorfunction(f)}
    assert generators == {"f_waits", "f_calls_waits", "f_joins", "_main"}
    assert {"f_plain", "f_calls_plain"} <= set(namespace)


def test_a_tabled_builtin_without_implementation_does_not_block() -> None:
    """sync with no implementation compiles (it stops the program when called): nothing waits on it."""
    program = compile_stub("def waits():\n  sync()\nend\nwaits()\n")
    namespace: dict[str, Any] = {}
    exec(program.code, {"__builtins__": {}}, namespace)
    assert not inspect.isgeneratorfunction(namespace["f_waits"])


def _wait_once(host: object) -> Iterator[None]:
    yield


def test_keywords_are_resolved_and_defaults_filled_at_compile_time() -> None:
    source = compile_stub("movej([1, 2, 3, 4, 5, 6], r=0.1, a=2)\nx = get_list()\n").source
    assert "b_movej(_L([1, 2, 3, 4, 5, 6]), 2, 1.05, 0, 0.1)" in source
    assert "b_get_list(_k0)" in source


def control_script(**overrides: Any) -> str:
    """Our control script as the daemon renders it (tool setup as in tests/test_urscript.py)."""
    fields: dict[str, Any] = {
        "tool_setup": ("set_tool_voltage(24)", "set_tool_communication(True, 115200, 0, 1, 1.5, 3.5)"),
        "controller_version": (5, 15, 0),
    }
    return render_control_script(ScriptParameters("127.0.0.1", **(fields | overrides)))


def test_our_control_script_compiles_unwrapped_and_headless() -> None:
    script = control_script()
    assert compile_program(script, series="e", version=(5, 15)).kind == "line"
    command, program = headless_program(script).split("\n", 1)
    assert command == "stop program"
    assert compile_program(program, series="e", version=(5, 15)).kind == "def"


def test_our_control_script_rendered_for_cb3_compiles() -> None:
    script = render_control_script(ScriptParameters("127.0.0.1", controller_version=(3, 15, 0)))
    assert compile_program(script, series="cb3", version=(3, 15)).kind == "line"


def test_our_control_script_rendered_for_an_old_e_series_compiles() -> None:
    script = render_control_script(ScriptParameters("127.0.0.1", controller_version=(5, 4, 0)))
    assert compile_program(script, series="e", version=(5, 4)).kind == "line"


@pytest.mark.skipif(
    not RTDE_CONTROL_SCRIPT.exists(), reason="ur_rtde's captured script is not on this machine"
)
def test_ur_rtde_control_script_compiles() -> None:
    program = compile_program(RTDE_CONTROL_SCRIPT.read_text(encoding="ascii"), series="e", version=(5, 12))
    assert program.kind == "def"
    assert program.name == "rtde_control"


def test_deep_nesting_is_a_compile_error_not_a_crash() -> None:
    error = _refused("x = " + "[" * 5000 + "1" + "]" * 5000 + "\n")
    assert (error.line, error.column) == (1, 1)
    assert "nested too deeply" in error.message


def test_a_parameter_declared_global_stays_the_parameter() -> None:
    program = compile_stub("g = 1\ndef f(g):\n  global g = 2\n  return g\nend\nx = f(3)\n")
    host = SimpleNamespace(step_time=0.002, thread=0, message=lambda kind, text: None)
    run = program.start(host)
    run.step()
    assert (run.done, run.error) == (True, None)
    assert run.variable("x") == 2, "the assignment went to the parameter"
    assert run.variable("g") == 1, "the program's g is untouched"


def test_more_nested_loops_than_python_allows_is_a_compile_error() -> None:
    depth = 25
    text = "".join(" " * i + "while True:\n" for i in range(depth)) + "sync()\n" + "end\n" * depth
    error = _refused(text)
    assert "nested" in error.message
    assert error.line > 1


def test_a_function_defined_twice_is_refused_at_its_second_definition() -> None:
    error = _refused("def f():\n  return 1\nend\ndef f():\n  return 2\nend\nf()\n")
    assert (error.line, error.column) == (4, 1)
    assert "f is already defined" in error.message


def test_a_program_larger_than_the_fake_compiles_is_refused_before_parsing() -> None:
    from urdaemon.fakeur.urscript.compiler import MAX_PROGRAM_CHARS

    error = _refused("x = 1\n" * (MAX_PROGRAM_CHARS // 6 + 1))
    assert (error.line, error.column) == (1, 1)
    assert f"at most {MAX_PROGRAM_CHARS}" in error.message
