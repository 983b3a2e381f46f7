"""The shipped cell files, compose.yaml and docs/ursim.md agree with each other (no Docker is run)."""

from __future__ import annotations

import dataclasses
import ipaddress
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from urdaemon.cell import Cell, load_cell
from urdaemon.errors import ConfigError
from urdaemon.fakeur.controller import FakePorts

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"
FAKE = CONFIGS / "dual_robot_fake.yaml"
URSIM = CONFIGS / "dual_robot_ursim.yaml"
COMPOSE = REPO / "compose.yaml"
URSIM_DOC = REPO / "docs" / "ursim.md"

ROLES = ("reverse", "script_sender", "trajectory", "script_command")
MODELS = {"alice": "ur10e", "bob": "ur3e"}
PORTS = {
    "alice": {"reverse": 50001, "script_sender": 50002, "trajectory": 50003, "script_command": 50004},
    "bob": {"reverse": 50011, "script_sender": 50012, "trajectory": 50013, "script_command": 50014},
}
FAKE_ADDRESSES = {"alice": "127.0.0.5", "bob": "127.0.0.6"}
URSIM_ADDRESSES = {"alice": "10.5.0.5", "bob": "10.5.0.6"}
DAEMON_ADDRESS = "10.5.0.2"
URSIM_SUBNET = ipaddress.ip_network("10.5.0.0/24")
URSIM_ROBOT_MODEL = {"alice": "UR10", "bob": "UR3"}
"""URSim e-Series' ROBOT_MODEL names the size; the image simulates the e-Series arm of that size."""
URSIM_SERVICE_PORTS = {"dashboard": 29999, "primary": 30001, "secondary": 30002, "rtde": 30004}
"""The URSim ports the daemon dials on each robot (docs/ursim.md)."""
URSIM_WEB_VNC = 6080
ZENOH_PORT = 7447


def compose() -> dict[str, Any]:
    data = yaml.safe_load(COMPOSE.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def service(name: str) -> dict[str, Any]:
    services = compose()["services"]
    assert isinstance(services, dict)
    svc = services[name]
    assert isinstance(svc, dict), f"service {name} is not a mapping"
    return svc


def ipv4(svc: dict[str, Any]) -> ipaddress.IPv4Address:
    address = ipaddress.ip_address(svc["networks"]["ursim_net"]["ipv4_address"])
    assert isinstance(address, ipaddress.IPv4Address)
    return address


def published(svc: dict[str, Any]) -> dict[int, int]:
    """Host port → container port of a service's short-syntax `ports` ("HOST:CONTAINER")."""
    out: dict[int, int] = {}
    for entry in svc.get("ports", []):
        assert isinstance(entry, str), f"expected 'HOST:CONTAINER', got {entry!r}"
        host, container = entry.rsplit(":", 2)[-2:]
        out[int(host)] = int(container)
    return out


def command_words(svc: dict[str, Any]) -> list[str]:
    command = svc["command"]
    words = command.split() if isinstance(command, str) else command
    assert isinstance(words, list)
    return [str(w) for w in words]


def ports_named_in(text: str) -> set[int]:
    return {int(m) for m in re.findall(r"(?<![\d.])(\d{4,5})(?![\d.])", text)}


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("*.yaml")), ids=lambda p: p.name)
def test_every_shipped_cell_file_loads(path: Path) -> None:
    cell = load_cell(path)
    assert cell.robots
    assert len({r.name for r in cell.robots}) == len(cell.robots)


def test_the_two_new_cell_files_are_shipped() -> None:
    names = {p.name for p in CONFIGS.glob("*.yaml")}
    assert {"dual_robot_fake.yaml", "dual_robot_ursim.yaml", "dual_robot_mock.yaml"} <= names


@pytest.mark.parametrize(
    ("path", "addresses", "listen"),
    [
        (FAKE, FAKE_ADDRESSES, "tcp/127.0.0.1:7447"),
        (URSIM, URSIM_ADDRESSES, "tcp/0.0.0.0:7447"),
    ],
    ids=["fake", "ursim"],
)
def test_dual_ur_cells(path: Path, addresses: dict[str, str], listen: str) -> None:
    cell = load_cell(path)
    assert cell.cell == "fake_cell"
    assert cell.zenoh.mode == "peer"
    assert cell.zenoh.listen == (listen,)
    assert [r.name for r in cell.robots] == ["alice", "bob"]
    for robot in cell.robots:
        assert robot.backend == "ur"
        assert robot.model == MODELS[robot.name]
        assert robot.address == addresses[robot.name]
        assert robot.headless is True
        assert robot.ports.as_dict() == PORTS[robot.name]
        assert robot.pose.parent == "world"
    alice, bob = cell.robot("alice"), cell.robot("bob")
    assert alice.pose.xyz == (0.5, 0.0, 0.0)
    assert alice.pose.rpy == (0.0, 0.0, 0.0)
    assert bob.pose.xyz == (-0.5, 0.0, 0.0)
    assert bob.pose.rpy == pytest.approx((0.0, 0.0, 3.141592653589793))
    every_port = [p for r in cell.robots for p in r.ports.as_dict().values()]
    assert len(every_port) == len(set(every_port)) == 8, "a host port is used twice"


def test_ports_are_written_out_not_defaulted() -> None:
    """The cell files name every port, so reordering or adding robots cannot move them."""
    for path in (FAKE, URSIM):
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        for robot in raw["robots"]:
            assert robot["ports"] == PORTS[robot["name"]], path.name


def test_fake_and_ursim_cells_differ_only_in_addresses_and_zenoh_listen() -> None:
    fake, ursim = load_cell(FAKE), load_cell(URSIM)

    def without_addresses(cell: Cell) -> list[dict[str, Any]]:
        return [r.model_dump(exclude={"address"}) for r in cell.robots]

    assert without_addresses(fake) == without_addresses(ursim)
    assert fake.publish == ursim.publish
    assert fake.zenoh.model_dump(exclude={"listen"}) == ursim.zenoh.model_dump(exclude={"listen"})


def test_ursim_cell_addresses_are_on_the_compose_subnet() -> None:
    cell = load_cell(URSIM)
    for robot in cell.robots:
        assert robot.address is not None
        assert ipaddress.ip_address(robot.address) in URSIM_SUBNET
    subnets = [c["subnet"] for c in compose()["networks"]["ursim_net"]["ipam"]["config"]]
    assert subnets == [str(URSIM_SUBNET)]


def test_compose_robot_services_sit_at_the_ursim_cell_addresses() -> None:
    cell = load_cell(URSIM)
    for robot in cell.robots:
        svc = service(robot.name)
        assert svc["image"] == "universalrobots/ursim_e-series"
        assert svc["environment"]["ROBOT_MODEL"] == URSIM_ROBOT_MODEL[robot.name]
        assert str(ipv4(svc)) == robot.address
        targets = {str(v).rsplit(":", 1)[-1] for v in svc["volumes"]}
        assert {"/urcaps", "/ursim/programs"} <= targets


def test_compose_daemon_service() -> None:
    daemon = service("urdaemon")
    address = ipv4(daemon)
    assert str(address) == DAEMON_ADDRESS
    assert address in URSIM_SUBNET
    robot_addresses = {ipv4(service(name)) for name in URSIM_ADDRESSES}
    assert address not in robot_addresses
    assert all(a in URSIM_SUBNET for a in robot_addresses)
    words = command_words(daemon)
    assert words[:2] == ["urdaemon", "serve"]
    config = words[words.index("--config") + 1]
    assert (REPO / config).resolve() == URSIM.resolve()
    assert daemon["build"]["context"] == "."
    assert (REPO / daemon["build"].get("dockerfile", "Dockerfile")).is_file()
    depends = daemon["depends_on"]
    assert set(depends) == set(URSIM_ADDRESSES)


def test_dockerfile_runs_the_ursim_cell_from_the_repo_layout() -> None:
    text = (REPO / "Dockerfile").read_text(encoding="utf-8")
    assert re.search(r"^FROM python:3\.11-slim\b", text, re.MULTILINE)
    assert re.search(r"^RUN pip install \.\s*$", text, re.MULTILINE)
    assert "configs/dual_robot_ursim.yaml" in text
    copied = set(re.findall(r"^COPY (\S+)", text, re.MULTILINE))
    assert {"urdaemon", "resources", "configs"} <= copied  # what the wheel and the command need


def test_compose_publishes_only_web_vnc_and_zenoh() -> None:
    host_ports: list[int] = []
    for name in URSIM_ADDRESSES:
        ports = published(service(name))
        assert set(ports.values()) == {URSIM_WEB_VNC}, f"{name} publishes more than its web VNC"
        host_ports.extend(ports)
    daemon_ports = published(service("urdaemon"))
    assert daemon_ports == {ZENOH_PORT: ZENOH_PORT}
    host_ports.extend(daemon_ports)
    assert len(host_ports) == len(set(host_ports)), "two services publish the same host port"
    listen = load_cell(URSIM).zenoh.listen
    assert [e.rsplit(":", 1)[-1] for e in listen] == [str(ZENOH_PORT)]
    assert all(e.startswith("tcp/0.0.0.0:") for e in listen), "the published port needs all interfaces"


def test_compose_publishes_on_the_hosts_loopback_only() -> None:
    """Reproduction (issue 16): compose.yaml published Zenoh and the pendants' VNC on every host
    interface, so any machine that reached the host could command the arms."""
    for name, svc in compose()["services"].items():
        for entry in svc.get("ports", []):
            assert str(entry).startswith("127.0.0.1:"), f"{name} publishes {entry!r} beyond the host"


def test_no_zenoh_router_while_the_daemon_is_a_listening_peer() -> None:
    cell = load_cell(URSIM)
    images = {str(svc.get("image", "")) for svc in compose()["services"].values()}
    if cell.zenoh.mode == "client":
        assert any(i.startswith("eclipse/zenoh") for i in images)
    else:
        assert not any(i.startswith("eclipse/zenoh") for i in images)
        assert cell.zenoh.listen


def test_daemon_dials_only_ursim_ports_named_in_the_docs() -> None:
    """What the daemon reaches on a robot (the fake's defaults = UR's standard ports) is what URSim serves."""
    # the fake also serves the real-time interface (30003) for other clients, e.g. ur_rtde's scripts;
    # the daemon never dials it
    served = {f.name: getattr(FakePorts(), f.name) for f in dataclasses.fields(FakePorts)}
    dialled = {name: port for name, port in served.items() if name != "realtime"}
    assert dialled == URSIM_SERVICE_PORTS
    doc_ports = ports_named_in(URSIM_DOC.read_text(encoding="utf-8"))
    compose_ports = ports_named_in(COMPOSE.read_text(encoding="utf-8"))
    for port in dialled.values():
        assert port in doc_ports, f"docs/ursim.md does not name URSim port {port}"
        assert port in compose_ports, f"compose.yaml does not explain URSim port {port}"
    robot_host_ports = {p for r in load_cell(URSIM).robots for p in r.ports.as_dict().values()}
    assert not robot_host_ports & set(dialled.values()), "a connect-back port shadows a URSim port"


def test_docs_name_every_connect_back_port_and_the_commands() -> None:
    text = URSIM_DOC.read_text(encoding="utf-8")
    doc_ports = ports_named_in(text)
    for robot in load_cell(URSIM).robots:
        for role, port in robot.ports.as_dict().items():
            assert port in doc_ports, f"docs/ursim.md does not name {robot.name}'s {role} port {port}"
        assert robot.address is not None
        assert robot.address in text
    assert DAEMON_ADDRESS in text
    assert "docker compose up" in text
    assert "urdaemon fake-robot --config configs/dual_robot_fake.yaml" in text
    assert "Remote Control" in text
    for name, host_port in (("alice", 6080), ("bob", 6081)):
        assert f"http://localhost:{host_port}/vnc.html" in text
        assert host_port in published(service(name))


SECURE = CONFIGS / "secure_cell" / "secure_cell.yaml"
"""The TLS + mutual TLS + access control example (docs/security.md); its certs/ folder is made by the
docs' openssl commands, never committed."""


def test_the_secure_cell_loads_once_its_certificates_exist(tmp_path: Path) -> None:
    import trustme

    (tmp_path / "certs").mkdir()
    ca = trustme.CA()
    ca.cert_pem.write_to_path(str(tmp_path / "certs" / "ca.pem"))
    daemon = ca.issue_cert("127.0.0.1", common_name="urdaemon")
    daemon.cert_chain_pems[0].write_to_path(str(tmp_path / "certs" / "daemon.pem"))
    daemon.private_key_pem.write_to_path(str(tmp_path / "certs" / "daemon-key.pem"))
    copy = tmp_path / SECURE.name
    copy.write_text(SECURE.read_text(encoding="utf-8"), encoding="utf-8")
    cell = load_cell(copy)
    assert cell.zenoh.tls is not None
    assert cell.zenoh.tls.mutual
    assert cell.zenoh.tls.certificate == str((tmp_path / "certs" / "daemon.pem").resolve())
    assert all(e.startswith("tls/127.0.0.1:") for e in cell.zenoh.listen)
    assert cell.zenoh.access is not None
    assert cell.zenoh.access.unknown_robots([r.name for r in cell.robots]) is None


def test_the_secure_cell_without_certificates_names_each_missing_file(tmp_path: Path) -> None:
    copy = tmp_path.resolve() / SECURE.name
    copy.write_text(SECURE.read_text(encoding="utf-8"), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_cell(copy)
    for field, name in (
        ("root_ca", "ca.pem"),
        ("certificate", "daemon.pem"),
        ("private_key", "daemon-key.pem"),
    ):
        assert any(
            f"zenoh.tls.{field}: file not found: {copy.parent / 'certs' / name}" in line
            and "docs/security.md" in line
            for line in info.value.errors
        ), info.value.errors
