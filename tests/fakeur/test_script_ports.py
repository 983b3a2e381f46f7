"""Judge: URScript sent to the controller's script ports runs, as a plain client (``nc``, python-urx)
sends it: bare lines on 30002 (secondary) and 30003 (real-time), a ``sec`` program beside a running
``def`` program, a ``def`` program replacing the running one, a compile error refused with its line.

What the scripts do is read back through our own RTDE codec (``RtdeWatch``: joint positions, digital
outputs, output registers) and primary reader (``PrimaryWatch``: the controller's messages), never
from the fake's insides. Reproduction on the code before issue 14: every bare line was answered
"compile_error_name_not_found" and a ``sec`` program was dropped; 30003 took no scripts.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from tests.fakeur.judges import FakeProcess, PrimaryWatch, RtdeWatch, fake_robot, send_script

pytestmark = pytest.mark.timeout(120)

PORTS = pytest.mark.parametrize("port", [30002, 30003], ids=["secondary", "realtime"])
OUTPUTS = (
    "actual_q",
    "actual_qd",
    "actual_digital_output_bits",
    "output_int_register_1",
    "output_int_register_2",
    "runtime_state",
)
PLAYING = 2
"""RTDE runtime_state of a running program."""

COUNTING = """def counting():
  n = 0
  while True:
    n = n + 1
    write_output_integer_register(1, n)
    sync()
  end
end
"""
"""A def program that counts its cycles in output register 1 for as long as it runs."""


@dataclass
class Judge:
    fake: FakeProcess
    rtde: RtdeWatch
    primary: PrimaryWatch

    def explain(self, what: str) -> str:
        return f"{what}\n{self.primary.describe()}\nfake log:\n{self.fake.log_tail()}"

    def counter(self) -> int:
        return int(self.rtde.sample["output_int_register_1"])

    def counting(self, samples: int = 5) -> bool:
        """Whether the counting program's register still grows over ``samples`` RTDE samples."""
        before = self.counter()
        self.rtde.next_samples(samples)
        return self.counter() > before


@pytest.fixture(params=[("ur10e", "5.15.0"), ("ur10", "3.15.7")], ids=["e-series", "cb3"])
def judge(request: pytest.FixtureRequest) -> Iterator[Judge]:
    model, version = request.param
    with fake_robot(model, "--powered", "--controller-version", version) as fake:
        primary = PrimaryWatch(fake.address)
        watch = RtdeWatch(fake.address, OUTPUTS, 125.0)
        try:
            watch.next_samples(1)
            yield Judge(fake, watch, primary)
        finally:
            watch.close()
            primary.close()


def _start_counting(judge: Judge, port: int) -> None:
    send_script(judge.fake.address, port, COUNTING)
    assert judge.rtde.wait_for(lambda: judge.counter() > 3, 20.0), judge.explain(
        "the def program did not run"
    )
    assert judge.counting(), judge.explain("the def program stopped counting")


@PORTS
def test_a_movej_line_runs(judge: Judge, port: int) -> None:
    target = [0.3, -1.4, 1.3, -1.5, -1.4, 0.2]
    send_script(judge.fake.address, port, f"movej({target}, a=1, v=1)\n")

    def arrived() -> bool:
        sample = judge.rtde.sample
        return bool(
            max(abs(a - b) for a, b in zip(sample["actual_q"], target, strict=True)) < 1e-3
            and max(abs(v) for v in sample["actual_qd"]) < 1e-6
        )

    assert judge.rtde.wait_for(arrived, 30.0), judge.explain(
        f"movej line on {port}: the arm is at {judge.rtde.sample['actual_q']}, target {target}"
    )
    assert not judge.primary.runtime_exceptions(), judge.explain("movej line")


@PORTS
def test_a_set_digital_out_line_runs(judge: Judge, port: int) -> None:
    send_script(judge.fake.address, port, "set_digital_out(2, True)\n")
    assert judge.rtde.wait_for(lambda: judge.rtde.sample["actual_digital_output_bits"] & 0b100 != 0, 10.0), (
        judge.explain(f"set_digital_out line on {port}")
    )
    assert not judge.primary.runtime_exceptions(), judge.explain("set_digital_out line")


@PORTS
def test_a_sec_program_runs_beside_a_running_def_program(judge: Judge, port: int) -> None:
    _start_counting(judge, port)
    send_script(
        judge.fake.address,
        port,
        "sec side():\n  set_digital_out(3, True)\n  write_output_integer_register(2, 7)\nend\n",
    )
    assert judge.rtde.wait_for(
        lambda: (
            judge.rtde.sample["output_int_register_2"] == 7
            and judge.rtde.sample["actual_digital_output_bits"] & 0b1000 != 0
        ),
        10.0,
    ), judge.explain("the sec program did not run")
    assert judge.counting(), judge.explain("the def program stopped when the sec program ran")
    assert judge.rtde.sample["runtime_state"] == PLAYING
    assert not judge.primary.runtime_exceptions(), judge.explain("sec beside def")


@PORTS
def test_a_def_program_replaces_the_running_one(judge: Judge, port: int) -> None:
    _start_counting(judge, port)
    send_script(
        judge.fake.address,
        port,
        "def other():\n  write_output_integer_register(2, 11)\n  while True:\n    sync()\n  end\nend\n",
    )
    assert judge.rtde.wait_for(lambda: judge.rtde.sample["output_int_register_2"] == 11, 10.0), judge.explain(
        "the second def program did not run"
    )
    assert not judge.counting(20), judge.explain("the first def program still counts: it was not replaced")
    assert judge.rtde.sample["runtime_state"] == PLAYING, "the new program runs"


@PORTS
def test_a_bare_line_replaces_the_running_program(judge: Judge, port: int) -> None:
    _start_counting(judge, port)
    send_script(judge.fake.address, port, "set_digital_out(4, True)\n")
    assert judge.rtde.wait_for(
        lambda: judge.rtde.sample["actual_digital_output_bits"] & 0b10000 != 0, 10.0
    ), judge.explain("the line did not run")
    assert not judge.counting(20), judge.explain("the def program still counts after a bare line")


@PORTS
def test_a_line_that_does_not_compile_is_refused_with_its_line_and_column(judge: Judge, port: int) -> None:
    send_script(judge.fake.address, port, "set_digital_outt(6, True)\n")
    assert judge.primary.wait_for(lambda: bool(judge.primary.runtime_exceptions()), 10.0), judge.explain(
        "no compile error for an unknown function in a line"
    )
    error = judge.primary.runtime_exceptions()[0]
    assert (error.line, error.column) == (1, 1), judge.explain("the error's line and column")
    assert "set_digital_outt" in error.text


@PORTS
def test_a_program_that_does_not_compile_never_starts(judge: Judge, port: int) -> None:
    script = "def broken():\n  set_digital_out(5, True)\n  set_digital_outt(6, True)\nend\n"
    send_script(judge.fake.address, port, script)
    assert judge.primary.wait_for(lambda: bool(judge.primary.runtime_exceptions()), 10.0), judge.explain(
        "no compile error for an unknown function in a program"
    )
    error = judge.primary.runtime_exceptions()[0]
    assert (error.line, error.column) == (3, 3), judge.explain("the error's line and column")
    assert "set_digital_outt" in error.text
    judge.rtde.next_samples(20)
    assert judge.rtde.sample["actual_digital_output_bits"] & 0b100000 == 0, "line 2 never ran"
    assert judge.rtde.sample["runtime_state"] != PLAYING, "no program runs"


@PORTS
def test_a_sec_program_that_moves_is_refused_and_the_def_program_runs_on(judge: Judge, port: int) -> None:
    """A secondary program may not use a physical instruction (the manual: no motion, no sleep)."""
    _start_counting(judge, port)
    send_script(judge.fake.address, port, "sec mover():\n  movej([0.3, -1.4, 1.3, -1.5, -1.4, 0.2])\nend\n")
    assert judge.primary.wait_for(lambda: bool(judge.primary.runtime_exceptions()), 10.0), judge.explain(
        "a sec program calling movej was not refused"
    )
    error = judge.primary.runtime_exceptions()[0]
    assert (error.line, error.column) == (2, 3), judge.explain("the error's line and column")
    assert judge.counting(), judge.explain("the def program stopped when the sec program was refused")
