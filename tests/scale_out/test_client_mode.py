"""A daemon as a Zenoh client of a router, in the cell file: it dials, listens nowhere, and refuses
what cannot work that way (a listen endpoint, access grants); configs/scale_out/ loads and checks."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import run_cli
from urdaemon.cell import load_cell, parse_cell
from urdaemon.errors import ConfigError
from urdaemon.publish.session_config import serve_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "scale_out"
ALICE = "robots: [{name: alice, model: ur5e, backend: mock}]\n"
ACCESS = (
    "access: {identities: {operator: {interfaces: [lo]}}, grants: [{identities: [operator], command: ['*']}]}"
)


def test_a_client_daemon_listens_nowhere_by_default() -> None:
    cell = parse_cell("cell: c\nzenoh: {mode: client, connect: ['tcp/10.5.0.1:7447']}\n" + ALICE)
    assert cell.zenoh.listen == ()
    assert cell.zenoh.connect == ("tcp/10.5.0.1:7447",)
    conf = serve_config(cell.zenoh, cell.zenoh.listen, cell.cell)
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("listen/endpoints")) == []
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/10.5.0.1:7447"]


def test_a_peer_still_listens_on_the_default_endpoint() -> None:
    assert parse_cell("cell: c\n" + ALICE).zenoh.listen == ("tcp/127.0.0.1:7447",)


@pytest.mark.parametrize(
    ("zenoh", "says"),
    [
        ("{mode: client}", "mode 'client' needs at least one connect endpoint"),
        (
            "{mode: client, connect: ['tcp/10.5.0.1:7447'], listen: ['tcp/127.0.0.1:7447']}",
            "a daemon in mode 'client' accepts no sessions",
        ),
        (
            "{mode: client, connect: ['tcp/10.5.0.1:7447'], " + ACCESS + "}",
            "grants cannot tell clients apart; put access control on the router",
        ),
        ("{mode: client, connect: ['tls/10.5.0.1:7447']}", "needs the 'tls' section"),
    ],
)
def test_what_a_client_daemon_cannot_do_is_refused(zenoh: str, says: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_cell(f"cell: c\nzenoh: {zenoh}\n" + ALICE)
    assert says in str(caught.value)
    assert "zenoh" in str(caught.value)


def test_access_on_a_listening_peer_still_loads() -> None:
    cell = parse_cell("cell: c\nzenoh: {" + ACCESS + "}\n" + ALICE)
    assert cell.zenoh.access is not None


def test_serve_listen_on_a_client_daemon_is_refused() -> None:
    """``urdaemon serve --listen`` overrides the cell file's endpoints; a client daemon has none to
    override."""
    cell = parse_cell("cell: c\nzenoh: {mode: client, connect: ['tcp/10.5.0.1:7447']}\n" + ALICE)
    with pytest.raises(ConfigError, match="accepts no sessions; cannot listen on"):
        serve_config(cell.zenoh, ("tcp/127.0.0.1:7447",), cell.cell)


@pytest.mark.parametrize(("name", "robot"), [("cell_a", "alice"), ("cell_b", "bob")])
def test_the_shipped_scale_out_cells_load_and_check(name: str, robot: str) -> None:
    path = CONFIGS / f"{name}.yaml"
    cell = load_cell(path)
    assert (cell.cell, [r.name for r in cell.robots]) == (name, [robot])
    assert (cell.zenoh.mode, cell.zenoh.listen, cell.zenoh.connect) == ("client", (), ("tcp/127.0.0.1:7447",))
    run = run_cli("check", "--config", str(path))
    assert run.code == 0, run.stderr
    assert "zenoh client listen=[] connect=['tcp/127.0.0.1:7447']" in run.stdout
