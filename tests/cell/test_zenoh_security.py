"""The cell file's ``zenoh.tls`` and ``zenoh.access``: what is refused (naming the key path), the
Zenoh config the daemon gets, the access rules a grant expands to, and the client config helper."""

from __future__ import annotations

import json
import stat
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.helpers import run_captured
from urdaemon.cell import load_cell
from urdaemon.errors import ConfigError
from urdaemon.publish.access import ANYONE, access_control
from urdaemon.publish.session_config import configure_daemon
from urdaemon.transport_security import client_config, client_config_main, write_client_config

TLS = "tls: {root_ca: ca.pem, certificate: daemon.pem, private_key: daemon-key.pem}"
ACCESS = (
    "access: {identities: {operator: {cert_common_names: [operator]}, "
    "viewer: {cert_common_names: [viewer]}}, "
    "grants: [{identities: [viewer], read: [alice]}, {identities: [operator], command: [alice]}]}"
)
ROBOTS = "robots: [{name: alice, model: ur5e, backend: mock}, {name: bob, model: ur3e, backend: mock}]"


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A cell folder with (dummy) certificate files: the schema checks they exist, not their content."""
    for name in ("ca.pem", "daemon.pem", "operator.pem"):
        (tmp_path / name).write_text("-----BEGIN CERTIFICATE-----\n", encoding="utf-8")
    for name in ("daemon-key.pem", "operator-key.pem"):
        (tmp_path / name).write_text("-----BEGIN PRIVATE KEY-----\n", encoding="utf-8")
    (tmp_path / "encrypted-key.pem").write_text("-----BEGIN ENCRYPTED PRIVATE KEY-----\n", encoding="utf-8")
    return tmp_path


def cell_file(folder: Path, zenoh_section: str) -> Path:
    path = folder / "cell.yaml"
    path.write_text(f"cell: sec\nzenoh: {{{zenoh_section}}}\n{ROBOTS}\n", encoding="utf-8")
    return path


SECURE = f'listen: ["tls/127.0.0.1:7447"], {TLS}'
GOOD = f"{SECURE}, {ACCESS}"


def error_of(folder: Path, zenoh_section: str) -> str:
    with pytest.raises(ConfigError) as info:
        load_cell(cell_file(folder, zenoh_section))
    return str(info.value)


@pytest.mark.parametrize(
    ("section", "names", "reason"),
    [
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS.replace("ca.pem", "nope/ca.pem")}',
            "zenoh.tls.root_ca",
            "not found",
        ),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS.replace("daemon-key.pem", "daemon.pem")}',
            "zenoh.tls.private_key",
            "holds no -----BEGIN PRIVATE KEY-----",
        ),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS.replace("daemon-key.pem", "encrypted-key.pem")}',
            "zenoh.tls.private_key",
            "holds no",
        ),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS.replace("ca.pem", "daemon-key.pem")}',
            "zenoh.tls.root_ca",
            "holds no -----BEGIN CERTIFICATE-----",
        ),
        ('listen: ["tls/127.0.0.1:7447"]', "listen[0]", "needs the 'tls' section"),
        (f'listen: ["tls/127.0.0.1:7447", "tcp/127.0.0.1:7448"], {TLS}', "listen[1]", "not encrypted"),
        (f'listen: [], connect: ["tcp/10.0.0.1:7447"], {TLS}', "tls", "no listen or connect endpoint"),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS[:-1]}, mutual: false}}, {ACCESS}',
            "access.identities.operator.cert_common_names",
            "mutual TLS",
        ),
        (
            f"{SECURE}, access: {{identities: {{op: {{cert_common_names: [o]}}}}, "
            "grants: [{identities: [nobody], read: [alice]}]}",
            "grants[0].identities",
            "unknown identity 'nobody'",
        ),
        (
            f"{SECURE}, access: {{identities: {{op: {{cert_common_names: [o]}}}}, "
            "grants: [{identities: [op]}]}",
            "zenoh.access.grants[0]",
            "needs 'read' or 'command'",
        ),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS}, access: {{identities: {{op: {{}}}}, grants: []}}',
            "zenoh.access.identities.op",
            "would match every connection",
        ),
        (
            f"{SECURE}, access: {{identities: {{op: {{cert_common_names: [o]}}}}, "
            "grants: [{identities: [op], command: [Alice]}]}",
            "zenoh.access.grants[0].command[0]",
            "pattern",
        ),
        (
            f'listen: ["tls/127.0.0.1:7447"], {TLS}, access: {{default: allow, '
            "identities: {op: {cert_common_names: [o]}}, grants: []}",
            "zenoh.access.default",
            "deny",
        ),
    ],
    ids=[
        "missing-file",
        "certificate-as-key",
        "encrypted-key",
        "key-as-ca",
        "tls-endpoint-without-tls",
        "tcp-beside-tls",
        "tls-unused",
        "common-names-without-mtls",
        "unknown-identity",
        "empty-grant",
        "identity-matching-all",
        "bad-robot-name",
        "default-allow",
    ],
)
def test_bad_security_settings_name_the_field(folder: Path, section: str, names: str, reason: str) -> None:
    message = error_of(folder, section)
    assert names in message, message
    assert reason in message, message
    assert "zenoh" in message, message


def test_certificate_paths_resolve_against_the_cell_files_folder(folder: Path) -> None:
    cell = load_cell(cell_file(folder, GOOD))
    assert cell.zenoh.tls is not None
    assert cell.zenoh.tls.root_ca == str((folder / "ca.pem").resolve())
    assert cell.zenoh.tls.mutual is True  # the secure default
    assert cell.zenoh.access is not None
    assert cell.zenoh.access.unknown_robots(["alice", "bob"]) is None
    unknown = str(cell.zenoh.access.unknown_robots(["bob"]))
    assert "zenoh.access.grants[0].read[0]: 'alice' is not a robot" in unknown


def _allowed(acl: dict[str, Any], subject: str, flow: str, message: str) -> set[str]:
    """The keys ``subject`` may send (ingress) or receive (egress) ``message`` on."""
    policies = [p for p in acl["policies"] if subject in p["subjects"]]
    rule_ids = {r for p in policies for r in p["rules"]}
    return {
        key
        for rule in acl["rules"]
        if rule["id"] in rule_ids and flow in rule["flows"] and message in rule["messages"]
        for key in rule["key_exprs"]
    }


def test_grants_expand_to_the_exact_keys_of_the_cell(folder: Path) -> None:
    """ "command alice" is alice's goals (issue 17: linear goals and twists too), services, streams,
    lease and lease token; "read alice"
    is her state, events, goal messages and results; nobody may publish a goal result or feedback
    (a forged result cannot enter through the daemon's links), and stop and a robot's cancel (it only
    stops, issue 32) are everyone's."""
    cell = load_cell(cell_file(folder, GOOD))
    assert cell.zenoh.access is not None
    acl = access_control(cell.zenoh.access, "sec")
    assert (acl["enabled"], acl["default_permission"]) == (True, "deny")
    queries = _allowed(acl, "operator", "ingress", "query")
    assert {
        "sec/alice/goal/move",
        "sec/alice/goal/linear",
        "sec/alice/goal/trajectory",
        "sec/alice/service/*",
        "sec/alice/lease",
        "sec/alice/goal/*/result",
    } <= queries
    assert not any(key.startswith("sec/bob/") for key in queries)
    assert _allowed(acl, "operator", "ingress", "put") == {
        "sec/alice/command/joint_position",
        "sec/alice/command/joint_velocity",
        "sec/alice/command/twist",
        "sec/alice/command/freedrive",
    }
    assert _allowed(acl, "operator", "ingress", "liveliness_token") == {"sec/alice/lease/*"}
    assert _allowed(acl, "viewer", "ingress", "put") == set()
    assert _allowed(acl, "viewer", "ingress", "query") == {
        "sec/alice/goal/*/result",
        "sec/alice/service/cycle_stats",
        "sec/alice/service/doctor",
        "sec/robot_description",
        "sec/daemon",  # what urdaemon list and info read
    }
    assert "sec/tf" not in _allowed(acl, "viewer", "ingress", "declare_subscriber")  # bob's poses too
    assert "sec/alice/joint_states" in _allowed(acl, "viewer", "ingress", "declare_subscriber")
    assert "sec/alice/goal/*/*" in _allowed(acl, "viewer", "egress", "put")
    assert _allowed(acl, ANYONE, "ingress", "query") == {
        "sec/*/service/stop",
        "sec/*/goal/cancel",
        "sec/service/stop",
        "sec/goal/cancel",  # a cancel only stops: no command grant needed (issue 32)
    }
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects[ANYONE] == {"id": ANYONE}
    assert subjects["operator"] == {"id": "operator", "cert_common_names": ["operator"]}


def test_every_robot_and_cell_goals_with_a_star(folder: Path) -> None:
    section = GOOD.replace("command: [alice]", 'command: ["*"]')
    access = load_cell(cell_file(folder, section)).zenoh.access
    assert access is not None
    acl = access_control(access, "sec")
    queries = _allowed(acl, "operator", "ingress", "query")
    assert {"sec/*/goal/move", "sec/goal/trajectory", "sec/robot_description"} <= queries
    assert "sec/goal/cancel" in _allowed(acl, ANYONE, "ingress", "query")  # every link may cancel
    assert "sec/goal/trajectory" not in _allowed(acl, "viewer", "ingress", "query")


def test_the_daemon_config_carries_tls_and_access_control(folder: Path) -> None:
    cell = load_cell(cell_file(folder, GOOD))
    conf = zenoh.Config()
    configure_daemon(conf, cell.zenoh, cell.cell)
    tls = json.loads(conf.get_json("transport/link/tls"))
    assert tls["root_ca_certificate"] == str((folder / "ca.pem").resolve())
    assert tls["listen_certificate"] == tls["connect_certificate"] == str((folder / "daemon.pem").resolve())
    assert tls["enable_mtls"] is True
    acl = json.loads(conf.get_json("access_control"))
    assert acl["enabled"] is True
    assert any("sec/alice/goal/move" in rule["key_exprs"] for rule in acl["rules"])
    untouched = zenoh.Config()
    configure_daemon(untouched, load_cell(cell_file(folder, 'listen: ["tcp/127.0.0.1:7447"]')).zenoh)
    assert json.loads(untouched.get_json("access_control/enabled")) is False


def test_the_client_config_names_the_ca_the_certificate_and_the_endpoint(folder: Path) -> None:
    cell = load_cell(cell_file(folder, GOOD))
    out = write_client_config(
        cell,
        certificate=str(folder / "operator.pem"),
        private_key=str(folder / "operator-key.pem"),
        path=folder / "op.json5",
    )
    assert stat.S_IMODE(out.stat().st_mode) == 0o600  # it names a private key
    data = json.loads(out.read_text(encoding="utf-8"))
    assert data["mode"] == "client"
    assert data["connect"]["endpoints"] == ["tls/127.0.0.1:7447"]
    tls = data["transport"]["link"]["tls"]
    assert tls["root_ca_certificate"] == str((folder / "ca.pem").resolve())
    assert tls["connect_private_key"] == str((folder / "operator-key.pem").resolve())
    assert tls["enable_mtls"] is True
    zenoh.Config.from_file(str(out))  # Zenoh reads it


@pytest.mark.parametrize(
    ("section", "kwargs", "reason"),
    [
        ('listen: ["tcp/127.0.0.1:7447"]', {}, "zenoh.tls is not set"),
        (GOOD, {"certificate": None}, "mutual TLS: give the client's certificate"),
        (GOOD.replace("127.0.0.1", "0.0.0.0"), {}, "--endpoint"),
        (GOOD, {"private_key": "missing.pem"}, "private key file not found"),
    ],
    ids=["no-tls", "mtls-without-certificate", "every-interface", "missing-key"],
)
def test_bad_client_configs_say_why(folder: Path, section: str, kwargs: dict[str, Any], reason: str) -> None:
    cell = load_cell(cell_file(folder, section))
    args: dict[str, Any] = {
        "certificate": str(folder / "operator.pem"),
        "private_key": str(folder / "operator-key.pem"),
    }
    args.update(kwargs)
    with pytest.raises(ConfigError, match=reason):
        client_config(cell, **args)


def test_client_config_command(folder: Path) -> None:
    path = cell_file(folder, GOOD)
    out = folder / "client.json5"
    args = ["--config", str(path), "--certificate", str(folder / "operator.pem")]
    args += ["--private-key", str(folder / "operator-key.pem"), "--output", str(out)]
    run = run_captured(lambda: client_config_main(args))
    assert run.code == 0, run.stderr
    assert out.is_file()
    assert str(out) in run.stdout
    bad = run_captured(lambda: client_config_main(["--config", str(path), "--output", str(out)]))
    assert bad.code == 2
    assert "give the client's certificate" in bad.stderr


def test_a_grant_naming_a_robot_the_cell_lacks_is_refused_naming_the_grant(folder: Path) -> None:
    """A grant's robot must be one of the cell's: before this check a misspelt robot (``carol``) was
    accepted and its grant silently matched nothing, so the operator could command no robot at all."""
    access = ACCESS.replace("command: [alice]", "command: [alice, carol]")
    message = error_of(folder, f"{SECURE}, {access}")
    assert "zenoh.access.grants[1].command[1]: 'carol' is not a robot of this cell" in message
