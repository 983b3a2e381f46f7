"""Mutual TLS through the router (docs/scale-out.md, "TLS and access control"): the router listens on
``tls/`` with the site's CA and its own certificate; a daemon in client mode dials it with its cell
file's ``tls`` section (its certificate is its identity to the router); a client whose Zenoh config
``client_config`` wrote for the router's endpoint moves the robot; a certificate of another CA, or
none, gets no session.

Access control on the router (the cell file refuses it in client mode): the rules a peer daemon
would get from its grants, on the router's links, plus a subject for the daemon's own link.

Certificates come from trustme (a throw-away CA per module): the router's for 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest
import trustme
import zenoh

from tests.helpers import zenoh_ask
from tests.scale_out.conftest import connected_with, serving, wait_alive
from urdaemon.cell import Cell, parse_cell
from urdaemon.cell.zenoh_options import AccessOptions
from urdaemon.publish.access import access_control
from urdaemon.router import Router, router_config
from urdaemon.transport_security import client_config

pytestmark = pytest.mark.timeout(180)

CELL_TEXT = """
cell: cell_a
zenoh:
  mode: client
  connect: ["{router}"]
  tls: {{root_ca: ca.pem, certificate: daemon.pem, private_key: daemon-key.pem}}
robots:
  - name: alice
    model: ur10e
    backend: mock
    mock: {{initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}}
"""
TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
CONNECT_TIMEOUT_MS = 5000


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("certs")
    ca, other_ca = trustme.CA(), trustme.CA()
    ca.cert_pem.write_to_path(str(folder / "ca.pem"))
    issued = {
        "router": ca.issue_cert("127.0.0.1", common_name="router"),
        "daemon": ca.issue_cert("cell-a.invalid", common_name="cell_a"),
        "operator": ca.issue_cert("operator.invalid", common_name="operator"),
        "viewer": ca.issue_cert("viewer.invalid", common_name="viewer"),
        "stranger": other_ca.issue_cert("operator.invalid", common_name="operator"),
    }
    for name, leaf in issued.items():
        leaf.cert_chain_pems[0].write_to_path(str(folder / f"{name}.pem"))
        leaf.private_key_pem.write_to_path(str(folder / f"{name}-key.pem"))
    router = {
        "root_ca_certificate": str(folder / "ca.pem"),
        "listen_certificate": str(folder / "router.pem"),
        "listen_private_key": str(folder / "router-key.pem"),
        "enable_mtls": True,
    }
    (folder / "router.json5").write_text(
        json.dumps({"transport": {"link": {"tls": router}}}), encoding="utf-8"
    )
    guarded = {"transport": {"link": {"tls": router}}, "access_control": _router_rules()}
    (folder / "router-access.json5").write_text(json.dumps(guarded), encoding="utf-8")
    return folder


ALL_MESSAGES = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]


def _router_rules() -> dict[str, Any]:
    """docs/scale-out.md's recipe: cell_a's grants as a peer daemon would enforce them (viewer reads,
    operator commands), and everything for the daemon's link (its certificate's CN ``cell_a``)."""
    access = AccessOptions.model_validate(
        {
            "identities": {
                "operator": {"cert_common_names": ["operator"]},
                "viewer": {"cert_common_names": ["viewer"]},
            },
            "grants": [
                {"identities": ["viewer"], "read": ["*"]},
                {"identities": ["operator"], "command": ["*"]},
            ],
        }
    )
    rules = access_control(access, "cell_a")
    rules["rules"].append(
        {
            "id": "daemons",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ALL_MESSAGES,
            "key_exprs": ["**"],
        }
    )
    rules["subjects"].append({"id": "daemons", "cert_common_names": ["cell_a"]})
    rules["policies"].append({"id": "daemons", "rules": ["daemons"], "subjects": ["daemons"]})
    return rules


def _client_file(cell: Cell, certs: Path, name: str, endpoint: str) -> Path:
    cert, key = str(certs / f"{name}.pem"), str(certs / f"{name}-key.pem")
    path = certs / f"{name}-client.json5"
    path.write_text(
        json.dumps(client_config(cell, certificate=cert, private_key=key, endpoint=endpoint)),
        encoding="utf-8",
    )
    return path


async def _open(path: Path) -> Any:
    conf = zenoh.Config.from_file(str(path))
    conf.insert_json5("connect/timeout_ms", json.dumps(CONNECT_TIMEOUT_MS))
    return await asyncio.get_running_loop().run_in_executor(None, zenoh.open, conf)


async def test_a_client_daemon_and_a_client_meet_on_a_mutual_tls_router(certs: Path) -> None:
    conf = router_config(["tls/127.0.0.1:0"], None, str(certs / "router.json5"))
    async with await Router.open(conf) as router:
        (endpoint,) = await router.locators()
        assert endpoint.startswith("tls/127.0.0.1:")
        cell = parse_cell(CELL_TEXT.format(router=endpoint), base_dir=certs)
        operator = _client_file(cell, certs, "operator", endpoint)
        async with serving([cell]) as site, connected_with(endpoint, operator) as client:
            await wait_alive(client, {"cell_a/alice"}, site)
            alice = await client.robot("alice", cell="cell_a")
            goal = await alice.move(TARGET, duration=1.0)
            assert (await goal.result(timeout=30.0))["status"] == "succeeded"
            stranger = _client_file(cell, certs, "stranger", endpoint)
            with pytest.raises(zenoh.ZError):
                (await _open(stranger)).close()
            plain = certs / "plain.json5"
            plain.write_text(
                json.dumps({"mode": "client", "connect": {"endpoints": [endpoint]}}), encoding="utf-8"
            )
            with pytest.raises(zenoh.ZError):
                (await _open(plain)).close()


async def test_access_control_on_the_router_lets_the_viewer_read_and_stop_but_not_command(
    certs: Path,
) -> None:
    conf = router_config(["tls/127.0.0.1:0"], None, str(certs / "router-access.json5"))
    async with await Router.open(conf) as router:
        (endpoint,) = await router.locators()
        cell = parse_cell(CELL_TEXT.format(router=endpoint), base_dir=certs)
        operator = _client_file(cell, certs, "operator", endpoint)
        viewer = _client_file(cell, certs, "viewer", endpoint)
        async with (
            serving([cell]) as site,
            connected_with(endpoint, operator) as op,
            connected_with(endpoint, viewer) as view,
        ):
            await wait_alive(op, {"cell_a/alice"}, site)
            states = view.subscribe("cell_a/alice/joint_states", 10)
            assert len((await states.get_json(timeout=10.0))["position"]) == 6, "the viewer reads"
            refused = await zenoh_ask(
                view.session, "cell_a/alice/goal/move", {"positions": TARGET}, timeout=3.0
            )
            assert refused == [], "the viewer's goal never reached the daemon"
            alice = await op.robot("alice", cell="cell_a")
            goal = await alice.move(TARGET, duration=30.0)
            stopped = await zenoh_ask(view.session, "cell_a/service/stop", {}, timeout=10.0)
            assert stopped == [{"v": 1, "ok": True, "robots": {"alice": {"ok": True}}}], "anyone may stop"
            result = await goal.result(timeout=10.0)
            assert (result["status"], result["reason"]) == ("aborted", "cell stop requested")
