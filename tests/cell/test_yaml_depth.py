"""Deeply nested YAML is refused with a clear error, never a ``RecursionError`` traceback (issue 32:
``check`` and ``serve`` crashed on it), in a cell file and in a calibration file."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import run_cli
from urdaemon.cell import parse_cell
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT
from urdaemon.description import load_calibration, load_ur_model
from urdaemon.errors import ConfigError

DEEP = 5000
"""Levels: far past Python's recursion limit."""
NESTED = {
    "flow list": "cell: " + "[" * DEEP + "]" * DEEP + "\n",
    "flow mapping": "cell: c\nrobots: " + "{a: " * DEEP + "1" + "}" * DEEP + "\n",
    "block mapping": "cell: c\nx:\n" + "".join("  " * i + "b:\n" for i in range(1, DEEP)),
}


@pytest.mark.parametrize("text", NESTED.values(), ids=list(NESTED))
def test_a_deeply_nested_cell_file_is_a_config_error_naming_the_line(text: str) -> None:
    with pytest.raises(
        ConfigError,
        match=r"cell\.yaml \(line \d+, column \d+\): not valid YAML: nested deeper "
        r"than 64 levels",
    ):
        parse_cell(text, source="cell.yaml")


def test_nesting_up_to_the_limit_is_yaml_like_any_other() -> None:
    text = "cell: c\nrobots: []\nx: " + "[" * 63 + "]" * 63 + "\n"
    with pytest.raises(ConfigError, match="x: unknown key"):
        parse_cell(text, source="cell.yaml")


@pytest.mark.parametrize("command", ["check", "serve"])
def test_check_and_serve_exit_2_with_one_line_and_no_traceback(command: str, tmp_path: Path) -> None:
    path = tmp_path / "deep.yaml"
    path.write_text(NESTED["flow list"], encoding="utf-8")
    run = run_cli(command, "--config", str(path))
    assert run.code == EXIT_BAD_INPUT, run
    assert "nested deeper than" in run.stderr
    assert "Traceback" not in run.stderr
    assert "RecursionError" not in run.stderr


def test_a_deeply_nested_calibration_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "calibration.yaml"
    path.write_text("dh: " + "[" * DEEP + "]" * DEEP + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="not valid YAML: nested deeper than"):
        load_calibration(path, load_ur_model("ur10e"))
