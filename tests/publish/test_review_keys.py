"""The key layout is parsed in one place, publish/keys.py (review of issue 13)."""

from __future__ import annotations

import pytest

from urdaemon.publish.keys import CellKeys, RobotKeys


@pytest.mark.parametrize(
    ("key", "parsed"),
    [
        ("cell/alice/service/stop", ("alice", ("service", "stop"))),
        ("cell/carol/goal/move", ("carol", ("goal", "move"))),
        ("cell/alice", ("alice", ())),
        ("cell/alice/goal/g-1/result", ("alice", ("goal", "g-1", "result"))),
        ("cell/tf", None),  # the cell's own keys name no robot
        ("cell/robot_description", None),
        ("cell/*/service/stop", None),  # a wildcard names no robot
        ("cell/alice/**", None),
        ("other/alice/service/stop", None),  # another cell's key
        ("cellar/alice/service/stop", None),
        ("cell", None),
    ],
)
def test_parse_splits_a_key_into_robot_and_rest(key: str, parsed: tuple[str, tuple[str, ...]] | None) -> None:
    """Reproduction: the daemon split ``<cell>/<robot>/...`` by hand in ``_on_any_robot``; keys.py
    had no parser, so ``CellKeys.parse`` did not exist."""
    keys = CellKeys("cell")
    assert keys.parse(key) == parsed
    assert keys.parse(keys.robot("bob").service("set_io")) == ("bob", ("service", "set_io"))


@pytest.mark.parametrize(
    ("rest", "service"),
    [
        (("service", "stop"), "stop"),
        (("goal", "move"), None),
        (("service",), None),
        (("service", "a", "b"), None),
    ],
)
def test_service_name_of_a_parsed_key(rest: tuple[str, ...], service: str | None) -> None:
    """Reproduction: as above; which chunks name a service was known only to the daemon."""
    assert CellKeys.service_name(rest) == service


@pytest.mark.parametrize(
    ("key", "goal_id"),
    [
        ("c/alice/goal/alice-x1-3/result", "alice-x1-3"),
        ("c/alice/goal/*/result", None),  # a wildcard query names no goal
        ("c/alice/goal/a/b/result", None),
        ("c/alice/goal//result", None),
        ("c/alice/goal/g1/feedback", None),
        ("c/bob/goal/g1/result", None),
        ("c/goal/g1/result", None),
    ],
)
def test_a_robot_result_key_names_its_goal(key: str, goal_id: str | None) -> None:
    keys = RobotKeys("c", "alice")
    assert keys.goal_of_result(key) == goal_id
    if goal_id is not None:
        assert keys.goal_result(goal_id) == key


@pytest.mark.parametrize(
    ("key", "goal_id"),
    [("c/goal/cell-7/result", "cell-7"), ("c/goal/*/result", None), ("c/alice/goal/g/result", None)],
)
def test_a_cell_result_key_names_its_goal(key: str, goal_id: str | None) -> None:
    assert CellKeys("c").goal_of_result(key) == goal_id
