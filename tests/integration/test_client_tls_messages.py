"""Issue 32, point 8: a TLS client is told what went wrong. The endpoint ``urdaemon client-config``
wrote into a ``--zenoh-config`` file is dialled unless ``--connect`` names another; a missing
certificate file, a client without a certificate (mutual TLS), the wrong CA and a name mismatch each
read as what they are, not "is the daemon running?"; a command the access rules deny says access
control may be why, not only "nothing serves".

Reproduction before: ``--zenoh-config`` alone dialled tcp/127.0.0.1:7447; every TLS failure read
"nothing answered within 5 s (is the daemon running and listening there?)"; a denied query read
"nothing at … serves …".
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import trustme

from tests.helpers import run_cli_in_thread
from tests.integration.test_client_tls import CLI_S, tls_cell
from tests.integration.test_transport_security import Certs, certs, secure_daemon
from urdaemon.client import Client
from urdaemon.errors import UrDaemonError
from urdaemon.transport_security import client_config

__all__ = ["certs"]  # the module's certificates (a fixture of test_transport_security)

pytestmark = pytest.mark.timeout(120)

CONNECT_S = 3.0
"""How long a client waits for its session before it says why there is none."""


def _write(path: Path, config: dict[str, Any]) -> str:
    path.write_text(json.dumps(config), encoding="utf-8")
    return str(path)


def _operator_config(folder: Path, endpoint: str, **tls: str) -> dict[str, Any]:
    link = {
        "root_ca_certificate": str(folder / "ca.pem"),
        "connect_certificate": str(folder / "operator.pem"),
        "connect_private_key": str(folder / "operator-key.pem"),
        "enable_mtls": True,
    }
    link.update(tls)
    return {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": {k: v for k, v in link.items() if v != ""}}},
    }


async def _refused(endpoint: str | None, config_file: str) -> str:
    with pytest.raises(UrDaemonError) as caught:
        async with await Client.connect(endpoint, config_file=config_file, timeout=CONNECT_S):
            pass
    return str(caught.value)


async def test_the_config_files_endpoint_is_dialled_unless_connect_names_another(tmp_path: Path) -> None:
    async with tls_cell(tmp_path) as cell:
        written = await run_cli_in_thread(
            "client-config", "--config", str(tmp_path / "cell.yaml"),
            "--certificate", str(tmp_path / "operator.pem"),
            "--private-key", str(tmp_path / "operator-key.pem"),
            "--output", cell.client_config, timeout=CLI_S,
        )  # fmt: skip
        assert written.code == 0, written
        lease = await run_cli_in_thread("lease", "alice", "--zenoh-config", cell.client_config, timeout=CLI_S)
        assert (lease.code, lease.stdout.strip()) == (0, "alice: free"), lease
        elsewhere = "tls/127.0.0.1:9"  # --connect still wins over the file
        other = await run_cli_in_thread(
            "lease", "alice", "--zenoh-config", cell.client_config, "--connect", elsewhere, timeout=CLI_S
        )
        assert other.code == 1, other
        assert f"cannot connect to {elsewhere}" in other.stderr, other


async def test_each_tls_failure_says_what_it_is(tmp_path: Path) -> None:
    async with tls_cell(tmp_path) as cell:
        folder, endpoint = tmp_path, cell.endpoint
        missing = _write(
            folder / "missing.json5", _operator_config(folder, endpoint, connect_certificate="/no/such.pem")
        )
        said = await _refused(None, missing)
        assert "the client certificate file /no/such.pem" in said, said
        assert "does not exist" in said, said
        mismatched = _write(
            folder / "mismatched.json5",
            _operator_config(folder, endpoint, connect_private_key=str(folder / "daemon-key.pem")),
        )
        said = await _refused(None, mismatched)
        assert "do not load together" in said, said
        no_certificate = _write(
            folder / "no-certificate.json5",
            _operator_config(
                folder, endpoint, connect_certificate="", connect_private_key="", enable_mtls=""
            ),
        )
        said = await _refused(None, no_certificate)
        assert "the daemon asks for a client certificate (mutual TLS) and this client gave none" in said, said
        assert "is the daemon running" not in said, said
        other_ca = trustme.CA()
        other_ca.cert_pem.write_to_path(str(folder / "other-ca.pem"))
        wrong_ca = _write(
            folder / "wrong-ca.json5",
            _operator_config(folder, endpoint, root_ca_certificate=str(folder / "other-ca.pem")),
        )
        said = await _refused(None, wrong_ca)
        assert "the daemon's certificate is not signed by the root CA" in said, said
        by_name = endpoint.replace("127.0.0.1", "localhost")  # its certificate names 127.0.0.1 only
        said = await _refused(by_name, _write(folder / "ok.json5", _operator_config(folder, endpoint)))
        assert "is not for 'localhost' (name mismatch" in said, said
        nobody = endpoint.rsplit(":", 1)[0] + ":9"
        said = await _refused(nobody, str(folder / "ok.json5"))
        assert "nothing accepts a connection at 127.0.0.1:9" in said, said


async def test_a_query_the_access_rules_deny_says_access_control_may_be_why(
    certs: Certs, tmp_path: Path
) -> None:
    async with secure_daemon(certs, lease=True) as secure:
        cert, key = certs.pair("viewer")  # may read alice, not command her
        config = client_config(secure.cell, certificate=cert, private_key=key, endpoint=secure.listen)
        path = _write(tmp_path / "viewer.json5", config)
        async with await Client.connect(secure.listen, config_file=path, timeout=10.0) as client:
            with pytest.raises(UrDaemonError) as caught:
                await client.request("seccell/alice/goal/move", {"positions": [0.0] * 6}, timeout=3.0)
            assert "access control" in str(caught.value), caught.value
            assert "seccell/alice/goal/move" in str(caught.value), caught.value
