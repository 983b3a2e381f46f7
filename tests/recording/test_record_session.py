"""``urdaemon record``'s pure choices from tables: which cell it records, what it subscribes to."""

from __future__ import annotations

import pytest

from urdaemon.errors import UrDaemonError
from urdaemon.recording.channels import recorded_keys
from urdaemon.recording.record_session import find_cell, key_expressions

SERVED = [("a", "alice"), ("a", "bob"), ("b", "carol")]
EP = "tcp/127.0.0.1:7447"


@pytest.mark.parametrize(
    ("served", "cell", "robots", "found"),
    [
        ([("a", "alice")], None, [], "a"),
        (SERVED, "b", [], "b"),
        (SERVED, "a", ["bob"], "a"),
        (SERVED, None, [], "several cells are served at tcp/127.0.0.1:7447 (a, b); name one with --cell"),
        ([], None, [], "no cell is served at tcp/127.0.0.1:7447"),
        (SERVED, "c", [], "no cell 'c' is served at tcp/127.0.0.1:7447; served: a, b"),
        (SERVED, "a", ["carol"], "no robot 'carol' in cell 'a'; its robots: alice, bob"),
    ],
)
def test_the_cell_recorded(
    served: list[tuple[str, str]], cell: str | None, robots: list[str], found: str
) -> None:
    if found in ("a", "b"):
        assert find_cell(served, cell, robots, EP) == found
    else:
        with pytest.raises(UrDaemonError) as err:
            find_cell(served, cell, robots, EP)
        assert str(err.value) == found


def test_every_recorded_key_without_a_choice() -> None:
    assert key_expressions("a", [], []) == list(recorded_keys("a"))


def test_named_robots_narrow_the_robot_keys_and_keep_the_cell_keys() -> None:
    keys = key_expressions("a", ["alice", "bob"], [])
    assert "a/alice/joint_states" in keys
    assert "a/bob/goal/*/result" in keys
    assert "a/tf" in keys
    assert "a/goal/*/result" in keys
    assert not any(k.startswith("a/*/") for k in keys)


def test_keys_are_under_the_cell_unless_they_name_it() -> None:
    assert key_expressions("a", [], ["alice/status", "a/bob/io", "*/events"]) == [
        "a/alice/status",
        "a/bob/io",
        "a/*/events",
    ]
