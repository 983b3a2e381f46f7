"""One name, one meaning (issue 31): no two modules of urdaemon/ share a basename, so a newcomer who
hears "arm.py" or "controller.py" knows which file is meant.

A basename may repeat only where it means the same job in each package (``SAME_JOB`` says which job).
Basenames still shared with two meanings, waiting for their owners to rename them, are listed in
``STILL_SHARED``; that list only shrinks: a new shared name fails, and a listed one that is no longer
shared must be taken off.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "urdaemon"

SAME_JOB: dict[str, str] = {
    "__init__": "a package's own module",
    "backend": "one kind of robot's Backend (backends/<kind>/backend.py)",
    "command": "the package's `urdaemon <command>` (its parser and its run)",
    # protocols/<name>/: the same three parts of each protocol's sans-IO codec, as h11 cuts them
    "_connection": "a protocol's connection state machine",
    "_events": "a protocol's events and messages",
    "_wire": "a protocol's byte layout",
}
"""Basenames that repeat with one meaning: the same job, one per package."""

STILL_SHARED: dict[str, set[str]] = {}
"""Basenames still shared with two meanings, and their modules today."""


def shared_basenames(root: Path) -> dict[str, set[str]]:
    """Basename → the modules (paths from ``root``'s parent) that have it, for each one held by more
    than one module under ``root``."""
    holders: defaultdict[str, set[str]] = defaultdict(set)
    for path in root.rglob("*.py"):
        holders[path.stem].add(path.relative_to(root.parent).as_posix())
    return {name: paths for name, paths in holders.items() if len(paths) > 1}


def test_no_two_modules_share_a_basename() -> None:
    shared = {name: paths for name, paths in shared_basenames(PACKAGE).items() if name not in SAME_JOB}
    new = {name: sorted(paths) for name, paths in shared.items() if paths != STILL_SHARED.get(name)}
    assert not new, f"modules sharing a basename (rename one by its job, or say why in SAME_JOB): {new}"


def test_the_list_names_only_basenames_still_shared() -> None:
    shared = shared_basenames(PACKAGE)
    gone = sorted(name for name in STILL_SHARED if name not in shared)
    assert not gone, f"no longer shared: take them off STILL_SHARED: {gone}"


def test_a_shared_basename_is_found(tmp_path: Path) -> None:
    """Two packages each with an ``arm.py``: found; the shared ``__init__`` is reported as well (the
    test above lets it pass through ``SAME_JOB``)."""
    package = tmp_path / "pkg"
    for sub in ("fake", "kinematics"):
        (package / sub).mkdir(parents=True)
        (package / sub / "__init__.py").write_text("")
    (package / "__init__.py").write_text("")
    (package / "fake" / "fake_arm.py").write_text("")
    (package / "kinematics" / "arm.py").write_text("")
    assert set(shared_basenames(package)) == {"__init__"}
    (package / "fake" / "arm.py").write_text("")  # the bad name
    assert shared_basenames(package)["arm"] == {"pkg/fake/arm.py", "pkg/kinematics/arm.py"}
