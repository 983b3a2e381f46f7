"""Where a UR robot's callback servers listen: the interface that reaches the robot, not every interface.

Until issue 16 the four servers listened on 0.0.0.0 unless ``ur.listen_address`` said otherwise. Now,
without it, they listen on the address that reaches the robot (``route.listen_plan``): for a robot on
this machine (every fake here, on a run-specific 127.x.y.z) that is the robot's own loopback address.
The end-to-end tests run ``UrBackend.run`` against a fake controller and wait, cycle by cycle, until
its control program holds all three links; addresses are loopback ones only.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import AsyncIterator
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from tests.ur.test_links_harness import HOME, JOINTS, UrRun, program_is_running, robot_config
from urdaemon.backends.ur import route, servers
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.cell.robot_options import UrOptions
from urdaemon.errors import BackendError, ConnectionLostError
from urdaemon.fakeur.controller import FakeController


@contextlib.asynccontextmanager
async def _running(address: str, ur: str, *, urcap_host: str | None = None) -> AsyncIterator[UrRun]:
    """A fake at ``address`` and a backend for it with options ``ur``, running; in URCap mode when
    ``urcap_host`` is given (the External Control URCap's Host IP)."""
    robot = robot_config(address, headless=urcap_host is None, ur=ur)
    urcap = None if urcap_host is None else (urcap_host, robot.ports.script_sender)
    fake = FakeController("ur10e", address=address, initial_positions=HOME, powered=True, urcap=urcap)
    await fake.start()
    run = UrRun(UrBackend(robot, JOINTS, expected_hash=None), fake)
    try:
        run.start()
        yield run
    finally:
        await run.stop()
        await fake.close()


def _bound(servers: CallbackServers) -> set[str]:
    """The addresses the servers' listening sockets are bound to."""
    found: set[str] = set()
    for server in servers.all:
        assert server._server is not None, f"the {server.name} server does not listen"
        found.update(str(sock.getsockname()[0]) for sock in server._server.sockets)
    return found


def _peers(servers: CallbackServers) -> set[str]:
    """The addresses the control program's links come from."""
    return {server.link.peer for server in servers.program_links if server.link is not None}


# ---- end to end: the backend against a fake controller ------------------------------------------------


async def test_by_default_the_servers_listen_on_the_robots_loopback_address(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Reproduction: a cell with no ``listen_address`` and a fake robot at 127.a.b.c. The servers'
    sockets were bound to 0.0.0.0 (every interface of the machine). Now they are bound to 127.a.b.c
    (the kernel would name 127.0.0.1 as the source towards it; the robot's connections come from its
    own address), the program connects back there from the robot's address, and the log says where
    and why."""
    address = fake_address()
    caplog.set_level(logging.INFO, logger="urdaemon.ur")
    async with _running(address, "{startup: true}") as run:
        await run.until(lambda: program_is_running(run), what="the program holds its links")
        assert _bound(run.backend.servers) == {address}
        assert _peers(run.backend.servers) == {address}
        dials = run.backend.diagnosis.link_facts()["callbacks"]["dials"]  # the doctor's view
        assert dials == address, "the program dials where the servers listen"
    said = [r.getMessage() for r in caplog.records if "callback servers listening" in r.getMessage()]
    assert said == [
        f"[alice] callback servers listening on {address}, the interface that reaches the robot at {address}"
    ]


async def test_an_explicit_listen_address_is_where_the_servers_listen_and_the_program_dials() -> None:
    """Reproduction: ``listen_address`` 127.a.b.d, another loopback address than the robot's
    127.a.b.c. The servers listened there, but the program was told to connect back to the daemon's
    end of its RTDE link (127.0.0.1), where nothing listened: it never connected and the robot never
    became ready. Now the program dials the address the servers listen on."""
    address, listen = fake_address(), fake_address()
    async with _running(address, f"{{startup: true, listen_address: {listen}}}") as run:
        await run.until(lambda: program_is_running(run), what="the program holds its links")
        assert _bound(run.backend.servers) == {listen}
        assert _peers(run.backend.servers) == {address}, "only the robot's address is accepted"


async def test_reverse_ip_of_this_machine_is_where_the_servers_listen() -> None:
    """Reproduction: ``reverse_ip`` 127.a.b.d (an address of this machine, not the robot's 127.a.b.c)
    and no ``listen_address``. The robot connects back to reverse_ip, so listening anywhere else would
    leave the program nothing to reach; the servers listened on 0.0.0.0. Now they listen on
    reverse_ip only, and the program's links arrive there from the robot's address."""
    address, reverse_ip = fake_address(), fake_address()
    async with _running(address, f"{{startup: true, reverse_ip: {reverse_ip}}}") as run:
        await run.until(lambda: program_is_running(run), what="the program holds its links")
        assert _bound(run.backend.servers) == {reverse_ip}
        assert _peers(run.backend.servers) == {address}


async def test_urcap_mode_fetches_the_script_from_the_robots_loopback_address() -> None:
    """Reproduction: URCap mode (the robot fetches the script from the script sender, whose Host IP is
    the robot's own 127.a.b.c here) with no ``listen_address``. The servers listened on 0.0.0.0. Now
    they listen on 127.a.b.c before RTDE connects, and the played program fetches its script and
    holds all its links."""
    address = fake_address()
    async with _running(address, "{startup: true}", urcap_host=address) as run:
        await run.until(lambda: program_is_running(run), what="the URCap's program holds its links")
        assert _bound(run.backend.servers) == {address}
        assert run.backend.servers.script_sender.refused == 0


async def test_a_new_route_to_the_robot_moves_the_servers_on_reconnect(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Reproduction: the servers listen on the interface that reached the robot; then the network
    changes (here: the route to it now names 127.a.b.d) and the RTDE link drops. The servers were
    started once and never moved. Now the next run places them again: they leave the old address
    (its ports close), listen on the new one, and the new program connects there."""
    address, moved = fake_address(), fake_address()
    async with _running(address, "{startup: true}") as run:
        await run.until(lambda: program_is_running(run), what="the program holds its links")
        port = run.backend.servers.reverse.port
        real = route.listen_plan

        def new_route(robot: str, options: UrOptions) -> route.ListenPlan:
            plan = real(robot, options)
            return route.ListenPlan(
                moved, plan.robot_ip, moved, f"the interface that reaches {plan.robot_ip}"
            )

        monkeypatch.setattr(servers, "listen_plan", new_route)
        assert run.fake.drop("rtde") == 1
        assert run.task is not None
        with pytest.raises(ConnectionLostError):  # the run ends with the lost link's error
            await run.until(lambda: False, timeout=20.0, what="the run ends")
        run.start()  # what the runtime does after its backoff
        await run.until(
            lambda: program_is_running(run) and _bound(run.backend.servers) == {moved},
            what="the new program holds its links on the new address",
        )
        assert _peers(run.backend.servers) == {address}
        with pytest.raises(ConnectionRefusedError):
            await asyncio.open_connection(address, port, local_addr=(address, 0))


# ---- the servers: listen, move, close ---------------------------------------------------------------


class _Hooks:
    def on_link(self, name: str, connected: bool, reason: str) -> None:
        return

    def on_event(self, name: str, event: Any) -> None:
        return


def _ports() -> dict[str, int]:
    return {name: free_tcp_port() for name in ("reverse", "script_sender", "trajectory", "script_command")}


async def test_servers_listen_moves_them_and_listening_again_is_nothing() -> None:
    """``CallbackServers.listen`` on another address closes the old one's ports and opens the new
    one's; on the same address it does nothing (no close, no new socket)."""
    first, second = fake_address(), fake_address()
    servers_ = CallbackServers(first, _ports(), _Hooks())
    try:
        assert await servers_.listen(first)
        sockets = [s._server for s in servers_.all]
        assert not await servers_.listen(first)
        assert [s._server for s in servers_.all] == sockets, "listening again restarted the servers"
        assert await servers_.listen(second)
        assert _bound(servers_) == {second}
        with pytest.raises(ConnectionRefusedError):
            await asyncio.open_connection(first, servers_.reverse.port)
    finally:
        await servers_.close()
    assert servers_.listening_on is None
    assert all(s._server is None for s in servers_.all)


# ---- the address function -----------------------------------------------------------------------------


def test_a_loopback_robot_is_reached_on_its_own_address_not_the_kernels_source() -> None:
    """The kernel's route to any 127.x.y.z names 127.0.0.1 as the source; the robot's connections come
    from its own address, so that is where the servers listen."""
    address = fake_address()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect((address, 9))  # what interface_toward does for other addresses; sends nothing
        assert probe.getsockname()[0] == "127.0.0.1"
    assert route.interface_toward(address) == address
    plan = route.listen_plan(address, UrOptions())
    assert (plan.address, plan.robot_ip, plan.connect_back) == (address, address, address)
    assert plan.why == f"the interface that reaches the robot at {address}"


def test_a_robot_host_name_is_resolved_first(monkeypatch: pytest.MonkeyPatch) -> None:
    """A host name in the cell file: the servers are placed for, and accept only, the IP it resolves
    to (stand-in resolver: no name lookup leaves the machine)."""
    address = fake_address()
    asked: list[str] = []

    def resolve(host: str, *_: Any, **__: Any) -> list[Any]:
        asked.append(host)
        return [(socket.AF_INET, socket.SOCK_STREAM, 6, "", (address, 0))]

    monkeypatch.setattr(socket, "getaddrinfo", resolve)
    plan = route.listen_plan("alice.cell.example", UrOptions())
    assert asked == ["alice.cell.example"]
    assert (plan.address, plan.robot_ip) == (address, address)


def test_a_robot_name_that_does_not_resolve_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(*_: Any, **__: Any) -> list[Any]:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", fail)
    with pytest.raises(BackendError, match=r"the robot's address 'alice\.cell\.example' does not resolve"):
        route.listen_plan("alice.cell.example", UrOptions())


def test_an_explicit_listen_address_is_taken_as_it_is() -> None:
    address, listen = fake_address(), fake_address()
    plan = route.listen_plan(address, UrOptions(listen_address=listen))
    assert (plan.address, plan.connect_back) == (listen, listen)
    every = route.listen_plan(address, UrOptions(listen_address="0.0.0.0"))
    assert (every.address, every.connect_back) == ("0.0.0.0", ""), "every interface: RTDE's end is dialled"
    both = route.listen_plan(address, UrOptions(listen_address="0.0.0.0", reverse_ip=listen))
    assert both.connect_back == listen


def test_reverse_ip_of_this_machine_wins_and_a_forwarded_one_does_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """reverse_ip is where the robot connects: an address of this machine is where the servers listen;
    one that is not (forwarded here, stood in for by the probe saying so) leaves them on the
    interface that reaches the robot, while the program still dials reverse_ip."""
    address, reverse_ip = fake_address(), fake_address()
    assert route.is_local_address(reverse_ip)
    plan = route.listen_plan(address, UrOptions(reverse_ip=reverse_ip))
    assert (plan.address, plan.connect_back) == (reverse_ip, reverse_ip)
    assert plan.why.startswith("ur.reverse_ip, the address the robot connects back to")
    same = route.listen_plan(address, UrOptions(reverse_ip=address))
    assert (same.address, same.connect_back) == (address, address)
    monkeypatch.setattr(route, "is_local_address", lambda host: False)
    forwarded = route.listen_plan(address, UrOptions(reverse_ip=reverse_ip))
    assert (forwarded.address, forwarded.connect_back) == (address, reverse_ip)
    assert "is not this machine's" in forwarded.why


def test_an_address_no_robot_can_have_is_refused() -> None:
    with pytest.raises(BackendError, match="not one a robot can have"):
        route.interface_toward("0.0.0.0")
