"""``ScriptRun.variable(name)``: a program variable's current value, for the controller and tests."""

from __future__ import annotations

import pytest

from tests.fakeur.urscript.test_runtime import start


def test_variable_reads_program_level_and_global_values_as_they_change() -> None:
    run, _ = start(
        "def p():\n  a = 1\n  def f():\n    global g = 5\n  end\n  f()\n  sync()\n  a = [1, 2]\nend\n"
    )
    with pytest.raises(KeyError, match="'a'"):
        run.variable("a")  # nothing ran yet
    run.step()
    assert run.variable("a") == 1
    assert run.variable("g") == 5
    run.step()
    assert run.variable("a") == [1, 2]
    with pytest.raises(KeyError, match="nothing"):
        run.variable("nothing")
