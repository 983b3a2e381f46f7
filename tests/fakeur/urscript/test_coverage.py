"""Every builtin of the table is simulated or refused with its reason, on every controller version."""

from __future__ import annotations

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.lib_unsimulated import NOT_SIMULATED, REASONS
from urdaemon.fakeur.urscript.runtime import BUILTINS
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import SERIES, all_signatures, load_signatures

DT = 0.002


def _versions(series: str) -> list[tuple[int, int]]:
    """Every version of ``series`` where the table changes (a function appears, goes or is renamed)."""
    found: set[tuple[int, int]] = set()
    for signature in all_signatures().values():
        for table in (signature.since, signature.until, signature.names_only):
            version = table.get(series)
            if version is not None:
                found.add((version[0], version[1]))
    return sorted(found)


@pytest.mark.parametrize("series", SERIES)
def test_every_builtin_of_every_version_is_implemented_or_listed_as_not_simulated(series: str) -> None:
    """On f5f0e26 76 builtins of e-Series 5.15 (and more of later versions) had no implementation and
    no documented reason: they stopped a program with a bare "not simulated"."""
    versions = _versions(series)
    assert versions, f"no versions of {series} in the table"
    unaccounted: dict[tuple[int, int], list[str]] = {}
    for version in versions:
        signatures = load_signatures(series, version)
        missing = sorted(name for name in signatures if name not in BUILTINS and name not in NOT_SIMULATED)
        if missing:
            unaccounted[version] = missing
    assert not unaccounted, (
        f"builtins neither implemented nor in lib_unsimulated.NOT_SIMULATED: {unaccounted}"
    )


def test_the_not_simulated_list_names_only_table_functions_that_nothing_implements() -> None:
    """A listed name that a library now implements (or that left the table) makes the list lie."""
    table = all_signatures()
    assert sorted(set(NOT_SIMULATED) - set(table)) == []
    implemented = sorted(
        name for name in NOT_SIMULATED if BUILTINS[name].function.__module__ != NOT_SIMULATED_MODULE
    )
    assert implemented == [], "implemented now: remove them from NOT_SIMULATED and the doc"
    assert sum(len(names) for names in REASONS.values()) == len(NOT_SIMULATED), "a name listed twice"


NOT_SIMULATED_MODULE = "urdaemon.fakeur.urscript.lib_unsimulated"


def test_a_listed_builtin_stops_the_program_saying_why() -> None:
    """Reproduction on f5f0e26: the message was only "encoder_get_tick_count: not simulated by the fake
    controller", with no reason."""
    model = load_ur_model("ur5e")
    host = ScriptHost(FakeArm(model, model.dh, powered=True), step_time=DT)
    run = compile_program("x = encoder_get_tick_count(0)\n", series="e", version=(5, 15)).start(host)
    for _ in range(5):
        if run.done:
            break
        run.step()
    assert run.done
    assert run.error is not None
    assert run.error.message == (
        "encoder_get_tick_count: not simulated by the fake controller: "
        "needs a conveyor encoder, which the fake has none of"
    )
    assert run.error.line == 1
