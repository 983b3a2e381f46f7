"""Mutual TLS through the router (docs/scale-out.md, "TLS and access control"): the router listens on
``tls/`` with the site's CA and its own certificate; a daemon in client mode dials it with its cell
file's ``tls`` section (its certificate is its identity to the router); a client whose Zenoh config
``client_config`` wrote for the router's endpoint moves the robot; a certificate of another CA, or
none, gets no session.

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

from tests.scale_out.conftest import connected_with, serving, wait_alive
from urdaemon.cell import Cell, parse_cell
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
    return folder


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
