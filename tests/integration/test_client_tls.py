"""The client and the CLI over mutual TLS (issue 16): ``urdaemon client-config`` writes the client's
Zenoh config, and every client command takes it as ``--zenoh-config`` next to ``--connect``.

Certificates come from trustme (a throw-away CA): the daemon's for 127.0.0.1 and a client's.
Reproduction on the code before: no client command could reach a TLS daemon (``--zenoh-config`` did
not exist, and ``Client.connect`` took no config).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import trustme

from tests.helpers import free_tcp_port, run_cli_in_thread
from urdaemon.cell import parse_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(120)

CELL_TEXT = """
cell: tlscell
zenoh:
  listen: ["{listen}"]
  tls: {{root_ca: ca.pem, certificate: daemon.pem, private_key: daemon-key.pem, mutual: true}}
robots:
  - name: alice
    model: ur10e
    backend: mock
    mock: {{initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}}
"""
AWAY = "0.2,-1.4,1.4,-1.5,-1.6,0.1"
CLI_S = 60.0


@dataclass(frozen=True)
class TlsCell:
    """A daemon on a ``tls/`` loopback endpoint with mutual TLS, its cell file and a client config."""

    daemon: Daemon
    endpoint: str
    folder: Path

    @property
    def client_config(self) -> str:
        return str(self.folder / "client.json5")


def _certificates(folder: Path) -> None:
    ca = trustme.CA()
    ca.cert_pem.write_to_path(str(folder / "ca.pem"))
    for name, leaf in (
        ("daemon", ca.issue_cert("127.0.0.1", common_name="urdaemon")),
        ("operator", ca.issue_cert("operator.invalid", common_name="operator")),
    ):
        leaf.cert_chain_pems[0].write_to_path(str(folder / f"{name}.pem"))
        leaf.private_key_pem.write_to_path(str(folder / f"{name}-key.pem"))


@asynccontextmanager
async def tls_cell(folder: Path) -> AsyncIterator[TlsCell]:
    """Serve the TLS cell on a free loopback port (written to ``folder/cell.yaml``)."""
    _certificates(folder)
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    text = CELL_TEXT.format(listen=endpoint)
    (folder / "cell.yaml").write_text(text, encoding="utf-8")
    daemon = Daemon(parse_cell(text, base_dir=folder), listen=(endpoint,))
    stop = asyncio.Event()
    task = asyncio.create_task(daemon.run(stop))
    try:
        yield TlsCell(daemon, endpoint, folder)
    finally:
        stop.set()
        await asyncio.wait_for(task, 20.0)


async def test_cli_commands_reach_a_mutual_tls_daemon_with_the_written_client_config(tmp_path: Path) -> None:
    async with tls_cell(tmp_path) as cell:
        written = await run_cli_in_thread(
            "client-config", "--config", str(tmp_path / "cell.yaml"),
            "--certificate", str(tmp_path / "operator.pem"),
            "--private-key", str(tmp_path / "operator-key.pem"),
            "--output", cell.client_config, timeout=CLI_S,
        )  # fmt: skip
        assert written.code == 0, written
        secure = ("--connect", cell.endpoint, "--zenoh-config", cell.client_config)
        move = await run_cli_in_thread(
            "move", "alice", "--joints", AWAY, "--duration", "0.6", *secure, timeout=CLI_S
        )
        assert move.code == 0, move
        assert '"succeeded"' in move.stdout, move
        lease = await run_cli_in_thread("lease", "alice", *secure, timeout=CLI_S)
        assert (lease.code, lease.stdout.strip()) == (0, "alice: free"), lease  # move released it
        async with await Client.connect(
            cell.endpoint, config_file=cell.client_config, timeout=10.0
        ) as client:
            alice = await client.robot("alice", timeout=10.0)
            assert len(await alice.ensure_lease()) == 32
        plain = await run_cli_in_thread("lease", "alice", "--connect", cell.endpoint, timeout=CLI_S)
        assert plain.code == 1, plain  # without the certificates it cannot connect at all
        assert cell.endpoint in plain.stderr, plain
