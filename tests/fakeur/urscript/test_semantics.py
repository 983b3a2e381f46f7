"""Operator precedence and value semantics, each point pinned with where it comes from.

"Source" points are what UR's own scripts rely on to work on a real controller (UR's client library's
external_control.urscript, ur_rtde's control script); "model" points have no public source and are the
interpreter's choice (Python's rule), kept so that a change to them is a decision, not an accident.
docs/fake-robot.md, "Operators and values", has the table.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.urscript.test_runtime import start
from urdaemon.fakeur.urscript import ScriptCompileError


def value(expression: str) -> Any:
    """What ``expression`` evaluates to in a one-line program."""
    run, host = start(f"record({expression})\n")
    run.step()
    assert run.error is None, run.error
    assert len(host.records) == 1
    return host.records[0][1]


# -- source: UR's own scripts rely on these --------------------------------------------------------------


def test_dividing_integers_gives_a_float() -> None:
    """external_control.urscript turns received integers into radians with ``raw / MULT_jointstate``
    (both ints): integer division would truncate every joint target to whole radians."""
    assert value("5 / 2") == 2.5
    assert value("1500000 / 1000000") == 1.5
    assert value("[3, 1] / 2") == [1.5, 0.5]


def test_comparisons_bind_tighter_than_and_or() -> None:
    """external_control.urscript: ``is_first_point and time == 0.0`` and
    ``result == SUCCESS and points_left > 0`` only work if the comparisons are taken first."""
    assert value("True and 0.0 == 0.0") is True
    assert value("1 == 1 and 2 > 1") is True
    assert value("False or 1 == 1") is True


def test_modulo_takes_floats_and_binds_like_multiplication() -> None:
    """external_control.urscript: ``counter * get_steptime() % 5.0 == 0`` is ``((a * b) % 5.0) == 0``."""
    assert value("3 * 2.5 % 5.0 == 2.5") is True
    assert value("10 % 4 * 2") == 4
    assert value("7.5 % 2") == 1.5


def test_multiplication_binds_tighter_than_addition_and_operators_are_left_associative() -> None:
    assert value("1 + 2 * 3") == 7
    assert value("10 - 4 - 3") == 3
    assert value("12 / 3 / 2") == 2.0
    assert value("-2 * 3 + 1") == -5


# -- model: no public source; the interpreter's choice, pinned -------------------------------------------


def test_not_is_taken_after_comparisons() -> None:
    """Model (Python's rule): ``not a == b`` is ``not (a == b)``."""
    assert value("not 1 == 2") is True
    assert value("not 1 == 1 and True") is False


def test_and_binds_tighter_than_or_and_xor() -> None:
    """Model: ``or``/``xor`` lowest, then ``and``; ``xor`` of two values is a boolean."""
    assert value("True or True and False") is True
    assert value("True xor True and False") is True
    assert value("1 xor 0") is True


def test_comparisons_do_not_chain() -> None:
    """Model: ``a < b < c`` is refused at compile time rather than guessed."""
    with pytest.raises(ScriptCompileError):
        start("record(1 < 2 < 3)\n")


@pytest.mark.parametrize(
    ("expression", "expected"),
    [
        ("-7 % 3", 2),  # floored, the sign of the divisor (C's fmod would give -1)
        ("7 % -3", -2),
        ("1 and 2", 2),  # and/or give an operand, as Python's do
        ("0 or 3", 3),
        ("1 == 1.0", True),
        ("[1, 2] + [3, 4]", [4, 6]),  # lists add element-wise, like their division by a scalar
        ("[1, 2] == [1, 2]", True),
        ("p[0.1, 0, 0, 0, 0, 0] == p[0.1, 0, 0, 0, 0, 0]", True),
        ('"a" + "b"', "ab"),
    ],
)
def test_value_semantics_the_interpreter_chose(expression: str, expected: Any) -> None:
    """Model points: see the table in docs/fake-robot.md for what is and is not known of a controller."""
    result = value(expression)
    assert result == expected
    assert type(result) is type(expected) or isinstance(result, list)


def test_dividing_by_zero_stops_the_program_with_a_runtime_error() -> None:
    run, _ = start("record(1 / 0)\n")
    run.step()
    assert run.error is not None
    assert "zero" in run.error.message.lower()
