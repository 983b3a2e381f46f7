"""The scheduler (ScriptRun): thread order, run/kill/join, critical sections, halt, the loop budget,
runtime errors with line and column, and URScript's value semantics."""

from __future__ import annotations

import time
from collections.abc import Generator, Iterator
from typing import Any, cast

import pytest

from tests.fakeur.urscript.test_compiler import STUB_TABLE, compile_stub
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.codegen import MAX_OPS_PER_CYCLE
from urdaemon.fakeur.urscript.lib_core import sleep, sync, textmsg
from urdaemon.fakeur.urscript.runtime import TOO_LONG, Builtin, ScriptRun, ScriptRuntimeError, UrList
from urdaemon.fakeur.urscript.signatures import Param, Signature


class Host:
    """What the scheduler and lib_core need of a ScriptHost; records what the program says."""

    def __init__(self) -> None:
        self.step_time = 0.002
        self.thread = -1
        self.messages: list[tuple[str, str]] = []
        self.records: list[tuple[int, Any]] = []

    def message(self, kind: str, text: str) -> None:
        self.messages.append((kind, text))


def _record(host: Host, value: Any) -> None:
    host.records.append((host.thread, value))


def _boom(host: Host, message: str) -> None:
    raise ScriptRuntimeError(message)


BUILTINS = {
    "sync": Builtin("sync", sync, blocking=True),
    "sleep": Builtin("sleep", sleep, blocking=True),
    "textmsg": Builtin("textmsg", textmsg, blocking=False),
    "record": Builtin("record", _record, blocking=False),
    "boom": Builtin("boom", _boom, blocking=False),
}


def start(text: str) -> tuple[ScriptRun, Host]:
    host = Host()
    return compile_stub(text, **BUILTINS).start(host), host


def cycles(run: ScriptRun, host: Host, count: int) -> list[list[tuple[int, Any]]]:
    """What each of ``count`` cycles recorded (thread handle, value)."""
    per_cycle = []
    for _ in range(count):
        host.records.clear()
        run.step()
        per_cycle.append(list(host.records))
    return per_cycle


def test_nothing_runs_before_the_first_step() -> None:
    run, host = start("record(1)\n")
    assert host.records == []
    assert run.threads == (0,)
    run.step()
    assert host.records == [(0, 1)]
    assert run.done
    assert run.error is None


def test_main_first_then_threads_in_start_order_a_new_thread_runs_in_its_cycle() -> None:
    run, host = start(
        """
thread a():
  while True:
    record("a")
    sync()
  end
end
thread b():
  while True:
    record("b")
    sync()
  end
end
ha = run a()
record("main")
sync()
hb = run b()
while True:
  record("main")
  sync()
end
"""
    )
    first, second, third = cycles(run, host, 3)
    assert first == [(0, "main"), (1, "a")]
    assert second == [(0, "main"), (1, "a"), (2, "b")]
    assert third == second


def test_kill_ends_a_thread_at_once_and_join_waits_for_the_end() -> None:
    run, host = start(
        """
thread counter():
  local n = 0
  while True:
    record(n)
    n = n + 1
    sync()
  end
end
thread short():
  sleep(0.006)
  record("short done")
end
h = run counter()
sync()
sync()
kill h
kill h
kill 0
record("killed")
s = run short()
join s
record("joined")
"""
    )
    per_cycle = cycles(run, host, 8)
    assert per_cycle[0] == [(1, 0)]
    assert per_cycle[1] == [(1, 1)]
    assert per_cycle[2] == [(0, "killed")]  # the counter never runs again; short starts and sleeps
    assert per_cycle[3] == []
    assert per_cycle[4] == []
    assert per_cycle[5] == [(2, "short done")]
    assert per_cycle[6] == [(0, "joined")]
    assert run.done
    assert run.error is None


def test_a_thread_killing_itself_ends_there() -> None:
    run, host = start(
        """
thread worker():
  record("before")
  kill me
  record("after")
end
me = run worker()
sync()
sync()
"""
    )
    assert cycles(run, host, 2) == [[(1, "before")], []]


def test_a_critical_section_is_never_interleaved_and_blocking_in_it_lets_others_run() -> None:
    """UR's External Control script (urcl) blocks in socket_read_binary_integer inside enter_critical in
    its main loop, and in servoj inside one in its servo thread; on a real controller both threads still
    run every cycle. Holding other threads off across a block would starve the servo thread for ever."""
    run, host = start(
        """
thread other():
  while True:
    enter_critical
    record("other in")
    record("other out")
    exit_critical
    sync()
  end
end
h = run other()
sync()
enter_critical
record("critical 1")
sync()
record("critical 2")
sync()
exit_critical
record("out")
sync()
"""
    )
    per_cycle = cycles(run, host, 4)
    assert per_cycle[0] == [(1, "other in"), (1, "other out")]
    assert per_cycle[1] == [(0, "critical 1"), (1, "other in"), (1, "other out")]
    assert per_cycle[2] == [(0, "critical 2"), (1, "other in"), (1, "other out")]
    assert per_cycle[3] == [(0, "out"), (1, "other in"), (1, "other out")]


def test_halt_ends_the_whole_program() -> None:
    run, host = start(
        """
thread other():
  while True:
    record("other")
    sync()
  end
end
h = run other()
sync()
halt
record("never")
"""
    )
    per_cycle = cycles(run, host, 3)
    assert per_cycle == [[(1, "other")], [], []]
    assert run.done
    assert run.error is None
    assert run.threads == ()


def test_the_main_program_ending_ends_its_threads() -> None:
    run, host = start(
        """
thread forever():
  while True:
    record("t")
    sync()
  end
end
run forever()
sync()
"""
    )
    assert cycles(run, host, 3) == [[(1, "t")], [], []]
    assert run.done


def test_stop_ends_the_program_between_cycles() -> None:
    run, host = start("while True:\n  record(1)\n  sync()\nend\n")
    run.step()
    run.stop()
    run.step()
    assert host.records == [(0, 1)]
    assert run.done
    assert run.error is None


def test_a_loop_without_sync_is_put_aside_each_cycle_and_resumes_where_it_stopped() -> None:
    """UR's manual (Thread scheduling): a thread that uses up its time slice by computing, "such as an
    infinite loop that do not control the robot", is placed in a non-runnable state until the next
    frame. Before, the fake stopped the program with an error after 100 000 iterations in one cycle."""
    run, _host = start(
        "x = 0\nthread spin():\n  while True:\n    x = x + 1\n  end\nend\nrun spin()\nsleep(1)\n"
    )
    run.step()
    first = run.variable("x")
    run.step()
    second = run.variable("x")
    assert (run.done, run.error) == (False, None)
    assert 0 < first < second


def test_a_loop_in_a_function_that_never_blocks_is_stopped_with_the_controllers_error() -> None:
    """A plain function cannot be put aside mid-loop: one that loops too long stops the program."""
    run, _host = start("x = 0\ndef f():\n  while True:\n    x = x + 1\n  end\nend\nf()\n")
    run.step()
    assert run.done
    assert run.error is not None
    assert run.error.message == TOO_LONG
    assert (run.error.line, run.error.column) == (3, 3)


def test_the_budget_is_per_cycle() -> None:
    """A loop that syncs every MAX_OPS_PER_CYCLE // 2 iterations runs for ever."""
    run, _host = start(
        f"n = 0\nwhile True:\n  n = n + 1\n  if n % {MAX_OPS_PER_CYCLE // 2} == 0:\n    sync()\n  end\nend\n"
    )
    for _ in range(4):
        run.step()
    assert not run.done
    assert run.error is None


def _ready(host: Host, number: int, socket_name: str, timeout: float) -> Generator[None, None, int]:
    """A socket read whose data is always there already: blocking, but it never has to wait."""
    if number < 0:  # never: makes this a generator that returns at once
        yield
    return 1


def test_a_waiting_loop_that_never_has_to_wait_sleeps_until_the_next_cycle() -> None:
    """A thread that uses up its time slice in a loop that may wait (a client flooding the socket it
    reads) is put aside until the next cycle, as the controller's scheduler does; the program goes on,
    and the next cycle it resumes where it stopped."""
    program = compile_stub(
        "n = 0\nwhile True:\n  n = n + socket_read_binary_integer(1)\nend\n",
        socket_read_binary_integer=Builtin("socket_read_binary_integer", _ready, True),
    )
    run = program.start(Host())
    run.step()
    assert (run.done, run.error) == (False, None)
    first = run.variable("n")
    assert 0 < first < MAX_OPS_PER_CYCLE  # a slice of the cycle, not a count of iterations
    run.step()
    assert (run.done, run.error) == (False, None)
    assert run.variable("n") > first


@pytest.mark.parametrize(
    ("text", "line", "column", "words"),
    [
        ("x = [1, 2, 3]\nrecord(1)\ny = x[3]\n", 3, 1, "Index out of bounds"),
        ("def f(a):\n  return 1 / a\nend\nrecord(1)\nf(0)\n", 2, 3, "Division by zero"),
        ('record(1)\nif True:\n  boom("it broke")\nend\n', 3, 3, "it broke"),
        ("record(1)\nabsent()\n", 2, 1, "absent: not simulated by the fake controller"),
        (
            "def f():\n  return y\nend\nrecord(1)\nf()\ny = 1\n",
            2,
            3,
            "Variable 'y' is used before it is given a value",
        ),
        ('record(1)\nx = 1 + "a"\n', 2, 1, "Type error"),
    ],
)
def test_runtime_errors_name_the_statements_line_and_column(
    text: str, line: int, column: int, words: str
) -> None:
    run, host = start(text)
    run.step()
    assert host.records == [(0, 1)]
    assert run.done
    assert run.error is not None
    assert words in run.error.message
    assert (run.error.line, run.error.column) == (line, column)


def test_an_error_in_a_thread_stops_the_whole_program() -> None:
    run, _host = start(
        'thread t():\n  sync()\n  boom("in thread")\nend\nrun t()\nwhile True:\n  sync()\nend\n'
    )
    run.step()
    assert run.threads == (0, 1)
    run.step()
    assert run.done
    assert run.error is not None
    assert run.error.message == "in thread"
    assert (run.error.line, run.error.column) == (3, 3)


def test_lists_are_values_assignment_and_arguments_copy() -> None:
    run, host = start(
        """
def scale(v, k):
  v[0] = v[0] * k
  return v
end
a = [1, 2]
b = a
b[0] = 5
c = scale(a, 10)
s = struct(q=[1, 2])
t = s
t.q[1] = 7
record(a)
record(b)
record(c)
record(s.q)
record(t.q)
"""
    )
    run.step()
    assert [value for _, value in host.records] == [[1, 2], [5, 2], [10, 2], [1, 2], [1, 7]]


def test_scoping_globals_locals_and_global_declarations() -> None:
    run, host = start(
        """
g = 1
def set_g():
  g = 2
end
def local_g():
  local g = 3
  record(g)
end
def declares():
  global h = 4
end
def uses_param(g):
  g = g + 100
  return g
end
set_g()
local_g()
declares()
record(g)
record(h)
record(uses_param(1))
record(g)
"""
    )
    run.step()
    assert [value for _, value in host.records] == [3, 2, 4, 101, 2]


def test_operators_and_python_keywords_as_names() -> None:
    run, host = start(
        """
async = 3
type = 4
record(async + type * 2)
record(7 / 2)
record(7 % 3)
record(True xor False)
record(True xor True)
record(not 1 == 2)
record([1, 2] + [10, 20])
record(2 * [1, 2])
record(p[1, 2, 3, 0, 0, 0])
s = struct(lambda=1)
s.lambda = 2
record(s.lambda)
record(pi > 3.14)
"""
    )
    run.step()
    assert run.error is None
    values = [value for _, value in host.records]
    assert values[:6] == [11, 3.5, 1, True, False, True]
    assert values[6] == [11, 22]
    assert values[7] == [2, 4]
    assert repr(values[8]) == "p[1, 2, 3, 0, 0, 0]"
    assert all(isinstance(x, float) for x in values[8])
    assert values[9:] == [2, True]


def test_textmsg_reaches_the_host() -> None:
    run, host = start('textmsg("steptime ", 0.002)\ntextmsg([1, 2.5])\n')
    run.step()
    assert host.messages == [("text", "steptime 0.002"), ("text", "[1, 2.5]")]


def _wait(host: Host, cycles_: int) -> Iterator[None]:
    for _ in range(cycles_):
        yield


def test_sleep_waits_whole_cycles_of_controller_time() -> None:
    run, host = start("record(1)\nsleep(0.005)\nrecord(2)\nsleep(0)\nrecord(3)\n")
    per_cycle = cycles(run, host, 4)
    assert per_cycle == [[(0, 1)], [], [], [(0, 2), (0, 3)]]


def test_a_name_the_compiler_knows_but_the_controller_lacks_fails_when_called() -> None:
    """CB3 3.14+ compiles e-Series names (urcl's script guards them at run time): calling one is an error."""
    table = dict(STUB_TABLE)
    table["e_only"] = Signature("e_only", (), False, {"e": (5, 0)}, supported=False)
    implementations = dict(BUILTINS, e_only=Builtin("e_only", _record, blocking=False))
    text = "if False:\n  e_only()\nend\nrecord(1)\ne_only()\n"
    program = compile_program(text, "cb3", (3, 15), signatures=table, builtins=implementations)
    host = Host()
    run = program.start(cast(Any, host))
    run.step()
    assert host.records == [(0, 1)]
    assert run.error is not None
    assert run.error.message == "e_only: not available on this controller (CB3 3.15)"
    assert (run.error.line, run.error.column) == (5, 1)


def test_builtins_keep_their_lists_when_the_program_mutates_its_own() -> None:
    """A builtin may return a list it keeps (the arm's joints) or keep a list it was given (a TCP)."""
    kept = UrList([1.0, 2.0])
    given: list[Any] = []
    table = dict(STUB_TABLE)
    table["keeper"] = Signature("keeper", (), False, {"e": (5, 0)})
    table["remember"] = Signature("remember", (Param("v"),), False, {"e": (5, 0)})
    implementations = dict(
        BUILTINS,
        keeper=Builtin("keeper", lambda host: kept, blocking=False),
        remember=Builtin("remember", lambda host, v: given.append(v), blocking=False),
    )
    text = "q = keeper()\nq[0] = 99\nremember(q)\nq[1] = 77\nrecord(q)\n"
    host = Host()
    compile_program(text, signatures=table, builtins=implementations).start(cast(Any, host)).step()
    assert host.records == [(0, [99, 77])]
    assert kept == [1.0, 2.0]
    assert given == [[99, 2.0]]


def test_list_arithmetic_is_element_wise_on_either_side() -> None:
    """URScript's + - * / on lists work element-wise, also with a plain list (a builtin's) on the left."""
    a = UrList([1.0, 2.0])
    plain: Any = [10, 20]
    assert a + plain == [11.0, 22.0]
    assert plain + a == [11.0, 22.0]
    assert isinstance(plain + a, UrList)
    assert plain - a == [9.0, 18.0]
    assert 1 - a == [0.0, -1.0]
    assert a / 2 == [0.5, 1.0]
    assert -a == [-1.0, -2.0]
    longer: Any = [1, 2, 3]
    with pytest.raises(ScriptRuntimeError, match="different lengths"):
        _ = a + longer
    with pytest.raises(ScriptRuntimeError, match="different lengths"):
        _ = longer * a


def _costly(host: Host, value: Any) -> None:
    """A builtin that takes a while (inverse kinematics, say): 1 ms of processor time each."""
    end = time.thread_time() + 0.001
    while time.thread_time() < end:
        pass


def test_a_loop_of_costly_calls_gives_up_its_slice_after_one_call_too_many() -> None:
    """The slice is time, read at every iteration: a loop calling a builtin that costs more than the
    whole slice (1 ms against 0.2 ms) makes two calls a cycle and goes on. Before, it held every fake's
    clock for 0.5 s of processor time, then stopped with the controller's error."""
    program = compile_stub(
        "n = 0\nwhile True:\n  n = n + 1\n  record(n)\nend\n", record=Builtin("record", _costly, False)
    )
    run = program.start(Host())
    for _ in range(3):
        run.step()
    assert (run.done, run.error) == (False, None)
    assert run.variable("n") <= 2 * 3  # one call past the slice, one more round to give it up


def test_a_list_default_is_made_anew_at_every_call() -> None:
    run, host = start("def f(a=[1, 2]):\n  a[0] = a[0] + 1\n  return a[0]\nend\nrecord(f())\nrecord(f())\n")
    run.step()
    assert [value for _, value in host.records] == [2, 2]


def test_a_thread_joining_itself_is_a_runtime_error_not_a_wait_for_ever() -> None:
    run, _host = start("h = 0\nthread t():\n  join h\nend\nh = run t()\nsleep(1)\n")
    for _ in range(3):
        run.step()
    assert run.error is not None
    assert "cannot wait for itself" in run.error.message
    assert (run.error.line, run.error.column) == (3, 3)


def test_a_nested_list_is_copied_whole_on_assignment() -> None:
    run, host = start("a = [[1, 2], [3, 4]]\nb = a\nb[0][0] = 9\nrecord(a[0][0])\nrecord(b[0][0])\n")
    run.step()
    assert run.error is None
    assert [value for _, value in host.records] == [1, 9]
