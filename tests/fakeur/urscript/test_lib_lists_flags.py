"""make_list and size (lists), and the program flags that outlive a program, through compiled scripts."""

from __future__ import annotations

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.script_host import ScriptHost


def _arm() -> FakeArm:
    model = load_ur_model("ur10e")
    return FakeArm(model, model.dh, powered=True)


def _run(arm: FakeArm, text: str) -> ScriptHost:
    host = ScriptHost(arm, step_time=0.002)
    run = compile_program(text, "e", (5, 15)).start(host)
    for _ in range(10):  # these programs end in their first cycle
        run.step()
        if run.done:
            break
    assert run.done
    assert run.error is None, run.error
    return host


def test_make_list_fills_copies_and_size_counts_them() -> None:
    arm = _arm()
    host = ScriptHost(arm, step_time=0.002)
    run = compile_program(
        "a = make_list(3, [0, 0])\na[0][1] = 5\nn = size(a)\nm = size(make_list(2, 1.5, 10))\n", "e", (5, 15)
    ).start(host)
    run.step()
    assert run.error is None
    assert run.variable("a") == [[0, 5], [0, 0], [0, 0]], "each element is its own copy"
    assert (run.variable("n"), run.variable("m")) == (3, 2)


def test_make_list_refuses_a_length_past_its_capacity() -> None:
    host = ScriptHost(_arm(), step_time=0.002)
    run = compile_program("a = make_list(5, 0, 2)\n", "e", (5, 15)).start(host)
    run.step()
    assert run.error is not None
    assert "capacity" in run.error.message


def test_a_flag_set_by_one_program_is_read_by_the_next() -> None:
    arm = _arm()
    _run(arm, "set_flag(3, True)\nset_flag(31, True)\nset_flag(31, False)\n")
    host = ScriptHost(arm, step_time=0.002)
    run = compile_program("three = get_flag(3)\nfour = get_flag(4)\n", "e", (5, 15)).start(host)
    run.step()
    assert run.error is None
    assert (run.variable("three"), run.variable("four")) == (True, False)
    assert arm.io.flags == 1 << 3
