"""The cell file's ``motion.cartesian``: caps and defaults of Cartesian motion, checked with key paths.

Reproduction: before issue 17 ``motion.cartesian`` was an unknown key of ``motion``.
"""

from __future__ import annotations

from dataclasses import fields

import pytest

from urdaemon.cell import parse_cell
from urdaemon.cell.robot_options import CARTESIAN_PAIRS
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.errors import ConfigError

ALICE = "cell: c\nrobots: [{name: alice, model: ur5e, backend: mock%s}]\n"


def test_the_defaults_are_the_contracts() -> None:
    options = parse_cell(ALICE % "").robot("alice").motion.cartesian
    caps = tuple(getattr(options, cap) for _, cap, _ in CARTESIAN_PAIRS)
    defaults = tuple(getattr(options, name) for name, _, _ in CARTESIAN_PAIRS)
    assert caps == (1.0, 5.0, 50.0, 3.0, 15.0, 150.0)
    assert defaults == (0.25, 1.2, 10.0, 1.0, 4.0, 40.0)


def test_the_pairs_name_the_limits_in_their_order() -> None:
    """A linear goal's limits are built as ``CartesianLimits(*values)`` in the pairs' order
    (runtime/pose_goals.py): each pair's default is the field at its place."""
    assert [name for name, _, _ in CARTESIAN_PAIRS] == [field.name for field in fields(CartesianLimits)]


def test_a_cell_file_sets_caps_and_defaults() -> None:
    text = ALICE % ", motion: {cartesian: {max_speed: 0.5, speed: 0.1, angular_jerk: 20}}"
    options = parse_cell(text).robot("alice").motion.cartesian
    assert (options.max_speed, options.speed, options.angular_jerk) == (0.5, 0.1, 20.0)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (
            "{speed: 2.0}",
            "robots[0] (alice).motion.cartesian: speed 2 m/s is above max_speed 1 m/s",
        ),
        (
            "{max_angular_jerk: 10}",
            "robots[0] (alice).motion.cartesian: angular_jerk 40 rad/s³ is above max_angular_jerk 10 rad/s³",
        ),
        ("{max_jerk: 0}", "robots[0] (alice).motion.cartesian.max_jerk: "),
        ("{jerk: -1}", "robots[0] (alice).motion.cartesian.jerk: "),
        ("{speed: .nan}", "robots[0] (alice).motion.cartesian.speed: "),
        ("{sped: 1}", "robots[0] (alice).motion.cartesian.sped: unknown key"),
    ],
)
def test_bad_cartesian_options_name_their_key_path(extra: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_cell(ALICE % f", motion: {{cartesian: {extra}}}")
    assert message in str(err.value)
