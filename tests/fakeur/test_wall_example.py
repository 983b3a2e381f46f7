"""The ``--wall`` example docs/fake-robot.md gives parses as written (a value starting with ``-`` must
be attached with ``=``: argparse takes ``--wall -0.69,...`` for two options)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

from urdaemon.cli.parser import build_parser
from urdaemon.fakeur.command import parse_wall

DOC = Path(__file__).resolve().parents[2] / "docs" / "fake-robot.md"


def test_the_documented_wall_example_parses() -> None:
    text = DOC.read_text(encoding="utf-8")
    examples = re.findall(r"`(--wall[= ][^`]*\d)`", text)
    assert examples, "docs/fake-robot.md gives no --wall example"
    for example in examples:
        args = build_parser().parse_args(["fake-robot", "--model", "ur10e", *shlex.split(example)])
        (wall,) = [parse_wall(value) for value in args.wall]
        assert wall is not None
