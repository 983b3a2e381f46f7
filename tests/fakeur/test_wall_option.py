"""``urdaemon fake-robot --wall -0.69,...`` parses as the docs first wrote it: a number list whose first
number is negative, as a separate word, is the option's value (cli/parser.py), for the number-list
options only.

Reproduction on the code before: argparse refused ``--wall -0.69,...`` ("expected one argument"), and
the pre-joining of ``--joints``/``--pose`` lived in entry.py, outside the parser.
"""

from __future__ import annotations

import pytest

from urdaemon.cli.parser import build_parser
from urdaemon.fakeur.command import parse_wall

WALL = "-0.69,-0.17,0.58,0,0,1"


def test_a_wall_starting_with_a_minus_sign_parses_as_a_separate_word() -> None:
    args = build_parser().parse_args(
        ["fake-robot", "--model", "ur10e", "--wall", WALL, "--wall", ".1,0,0,0,0,1"]
    )
    assert args.wall == [WALL, ".1,0,0,0,0,1"]
    assert parse_wall(args.wall[0]) is not None


def test_joints_starting_with_a_minus_sign_parse_through_the_parser() -> None:
    args = build_parser().parse_args(["move", "alice", "--joints", "-0.5,1,1,-1,1,0", "--duration", "3"])
    assert args.joints == "-0.5,1,1,-1,1,0"


def test_other_options_and_other_words_are_left_alone() -> None:
    """``--wall`` followed by an option is still a missing value, and a '-' word after another option
    is still an option (argparse's own rules)."""
    with pytest.raises(SystemExit):
        build_parser().parse_args(["fake-robot", "--model", "ur10e", "--wall", "--powered"])
    with pytest.raises(SystemExit):
        build_parser().parse_args(["fake-robot", "--model", "-0.5,1"])
