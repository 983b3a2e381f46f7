"""``check`` (and ``serve``) refuse the cells ``serve`` would fail on forever (issue 13, finding 6).

Reproductions on the code before the fix: ``urdaemon check`` said ``ok`` for a cell whose Zenoh
listen port is a robot's callback port, for two robots at one controller address, for an address
with a port (``127.0.0.5:30004``) and for a callback port another process already listens on; then
``serve`` retried the failing robot forever, with a traceback on every retry.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from tests.helpers import fake_address, free_tcp_port, run_cli
from urdaemon.cell import parse_cell
from urdaemon.errors import ConfigError


def _ur(name: str, address: str, ports: tuple[int, int, int, int], extra: str = "") -> str:
    reverse, sender, trajectory, command = ports
    return (
        f"  - {{name: {name}, model: ur5e, backend: ur, address: '{address}', "
        f"ports: {{reverse: {reverse}, script_sender: {sender}, trajectory: {trajectory}, "
        f"script_command: {command}}}, ur: {{listen_address: 127.0.0.1{extra}}}}}\n"
    )


def _ports() -> tuple[int, int, int, int]:
    return (free_tcp_port(), free_tcp_port(), free_tcp_port(), free_tcp_port())


def _refused(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_cell(text, source="cell.yaml")
    return caught.value.errors


def test_a_zenoh_listen_port_that_is_a_callback_port_is_refused() -> None:
    ports = _ports()
    text = f"cell: c\nzenoh: {{listen: ['tcp/127.0.0.1:{ports[2]}']}}\nrobots:\n" + _ur(
        "alice", "127.0.0.5", ports
    )
    errors = _refused(text)
    assert any(
        e.startswith("cell.yaml: zenoh.listen[0]:") and f"port {ports[2]}" in e and "trajectory" in e
        for e in errors
    ), errors


def test_a_zenoh_port_shared_with_a_read_only_robot_is_fine() -> None:
    """A read-only robot has no callback servers: its ports are never listened on."""
    ports = _ports()
    text = f"cell: c\nzenoh: {{listen: ['tcp/127.0.0.1:{ports[0]}']}}\nrobots:\n" + _ur(
        "alice", "127.0.0.5", ports, ", read_only: true"
    )
    assert parse_cell(text).robots[0].name == "alice"


def test_two_robots_at_one_controller_address_are_refused() -> None:
    text = "cell: c\nrobots:\n" + _ur("alice", "127.0.0.5", _ports()) + _ur("bob", "127.0.0.5", _ports())
    errors = _refused(text)
    assert any(
        e.startswith("cell.yaml: robots[1] (bob).address:") and "robot 'alice'" in e for e in errors
    ), errors


@pytest.mark.parametrize("address", ["127.0.0.5:30004", "robot.local:29999", "tcp://10.0.0.2", "a b"])
def test_an_address_with_a_port_or_scheme_is_refused(address: str) -> None:
    errors = _refused("cell: c\nrobots:\n" + _ur("alice", address, _ports()))
    assert any(e.startswith("cell.yaml: robots[0] (alice).address:") for e in errors), errors
    if address.rpartition(":")[2].isdigit():
        assert any("without a port" in e for e in errors), errors


@pytest.mark.parametrize("address", ["127.0.0.5", "::1", "ur10e-left.cell.local", "10.5.0.6"])
def test_plain_addresses_and_host_names_are_accepted(address: str) -> None:
    assert parse_cell("cell: c\nrobots:\n" + _ur("alice", address, _ports())).robots[0].address == address


def test_duplicate_callback_ports_across_robots_are_refused() -> None:
    ports = _ports()
    other = (free_tcp_port(), ports[1], free_tcp_port(), free_tcp_port())
    errors = _refused(
        "cell: c\nrobots:\n" + _ur("alice", "127.0.0.5", ports) + _ur("bob", "127.0.0.6", other)
    )
    assert any(e.startswith("cell.yaml: robots[1] (bob).ports.script_sender:") for e in errors), errors


def test_check_refuses_a_callback_port_in_use_and_serve_names_the_static_problem(tmp_path: Path) -> None:
    ports = _ports()
    config = tmp_path / "cell.yaml"
    config.write_text("cell: c\nrobots:\n" + _ur("alice", "127.0.0.5", ports), encoding="utf-8")
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", ports[0]))
        holder.listen()
        run = run_cli("check", "--config", str(config))
    assert run.code == 2, run
    assert f"robots[0] (alice).ports.reverse: cannot listen on 127.0.0.1:{ports[0]}" in run.stderr
    assert "ok" not in run.stdout.split()
    free = run_cli("check", "--config", str(config))
    assert free.code == 0, free
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "cell: c\nrobots:\n" + _ur("alice", "127.0.0.5", ports) + _ur("bob", "127.0.0.5", _ports()),
        encoding="utf-8",
    )
    serve = run_cli("serve", "--config", str(bad))
    assert serve.code == 2, serve
    assert "robots[1] (bob).address" in serve.stderr
    assert "Traceback" not in serve.stderr


def test_check_binds_where_serve_would_listen_by_default(tmp_path: Path) -> None:
    """With no ``listen_address`` the servers listen on the interface that reaches the robot (for a
    robot on this machine: its own loopback address), so ``check`` must try that address. Before,
    it tried 0.0.0.0: a port held on the robot's address was reported only by luck of the bind
    rules, and one held on another loopback address was reported though ``serve`` would not clash."""
    robot = fake_address()
    ports = _ports()
    config = tmp_path / "cell.yaml"
    config.write_text(
        "cell: c\nrobots:\n"
        f"  - {{name: alice, model: ur5e, backend: ur, address: '{robot}', ports: {{reverse: {ports[0]}, "
        f"script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}}}\n",
        encoding="utf-8",
    )
    with socket.socket() as elsewhere:  # another address of the machine: no clash for serve
        elsewhere.bind(("127.0.0.1", ports[1]))
        elsewhere.listen()
        with socket.socket() as holder:  # the robot's own address: serve would fail to listen
            holder.bind((robot, ports[0]))
            holder.listen()
            run = run_cli("check", "--config", str(config))
    assert run.code == 2, run
    assert f"robots[0] (alice).ports.reverse: cannot listen on {robot}:{ports[0]}" in run.stderr
    assert "ports.script_sender" not in run.stderr
