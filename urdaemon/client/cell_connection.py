"""``Client``: a program's connection to a urdaemon cell. It opens the Zenoh session on an endpoint,
finds the robots served (a ``RobotClient`` each), stops a whole cell, reads its URDF, and holds this
client's command lease on each robot, released on close.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Sequence
from typing import Any

import zenoh

from urdaemon.cell.zenoh_options import DEFAULT_ENDPOINT, SECURE_PROTOCOLS
from urdaemon.client.command_lease import Lease, default_holder, holder_text
from urdaemon.client.robot_client import RobotClient
from urdaemon.client.session import QUERY_TIMEOUT_S, ClientSession, zenoh_message
from urdaemon.client.tls_diagnosis import TlsFiles, tls_file_problem, tls_files, tls_handshake_problem
from urdaemon.errors import UrDaemonError, UrTimeoutError
from urdaemon.publish.keys import ALIVE_ANYWHERE, CellKeys, RobotKeys
from urdaemon.publish.session_config import zenoh_config

__all__ = ["DEFAULT_ENDPOINT", "PEER_WAIT_S", "RELEASE_ON_CLOSE_S", "STABLE_POLLS", "Client", "NoSuchRobot"]

PEER_WAIT_S = 0.05
RELEASE_ON_CLOSE_S = 2.0
"""How long ``Client.close()`` waits for each lease's release (the session's end frees it anyway)."""
STABLE_POLLS = 3
"""``Client.robot`` says a robot is not served once the served list stayed the same this many polls
(0.1 s apart) in a row; while it grows it keeps waiting, up to its timeout."""


class NoSuchRobot(UrDaemonError):
    """No daemon reachable from this client serves a robot of that name; ``robots`` lists what is served."""

    def __init__(self, message: str, robots: Sequence[tuple[str, str]] = ()) -> None:
        super().__init__(message)
        self.robots = list(robots)


class Client(ClientSession):
    """A Zenoh session connected to a urdaemon cell."""

    def __init__(
        self,
        session: Any,
        loop: asyncio.AbstractEventLoop,
        endpoint: str = DEFAULT_ENDPOINT,
        *,
        holder: str | None = None,
    ) -> None:
        super().__init__(session, loop, endpoint, default_holder() if holder is None else holder_text(holder))
        self._leases: dict[str, Lease] = {}

    @classmethod
    async def connect(
        cls,
        endpoint: str | None = None,
        *,
        timeout: float = 5.0,
        low_latency: bool = False,
        holder: str | None = None,
        config_file: str | None = None,
    ) -> Client:
        """Open a Zenoh session connected to ``endpoint`` (no multicast scouting); ``low_latency``
        to match a daemon whose cell sets ``zenoh: {low_latency: true}`` (half the CPU per sample
        for both; without it the client still works).

        ``config_file``: a Zenoh JSON5 configuration to start from (TLS certificates, docs/security.md);
        its endpoint (what ``urdaemon client-config`` wrote) is dialled unless another ``endpoint``
        than ``DEFAULT_ENDPOINT`` (every command's ``--connect`` default) is given; mode and scouting
        are set as above.
        ``holder``: how this client's leases name it (default: the program, its pid and host).

        Raises ``UrDaemonError`` naming the endpoint when nothing answers there within ``timeout`` s,
        and naming the cause when a TLS file is wrong or the TLS handshake fails (tls_diagnosis.py).
        """
        loop = asyncio.get_running_loop()
        base = _config_file(config_file)
        if endpoint in (None, DEFAULT_ENDPOINT):  # the default is no choice: a file's endpoint wins
            endpoint = _file_endpoint(base) or DEFAULT_ENDPOINT
        files = tls_files(base) if base is not None else None
        secure = endpoint.startswith(SECURE_PROTOCOLS)
        if files is not None and secure:
            problem = tls_file_problem(files, config_file)
            if problem is not None:
                raise UrDaemonError(f"cannot connect to {endpoint}: {problem}")
        try:
            conf = _session_config(endpoint, low_latency, base)
            conf.insert_json5("connect/timeout_ms", json.dumps(int(timeout * 1000)))
            session = await loop.run_in_executor(None, zenoh.open, conf)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot connect to {endpoint}: {zenoh_message(err)}") from err
        deadline = loop.time() + timeout
        while not _has_peer(session):  # a peer session opens even when nobody listens there
            if loop.time() >= deadline:
                await loop.run_in_executor(None, session.close)
                if secure:  # Zenoh does not say why: a handshake of our own does
                    why = await loop.run_in_executor(
                        None, tls_handshake_problem, endpoint, files or TlsFiles(None, None, None), timeout
                    )
                    raise UrDaemonError(f"cannot connect to {endpoint}: {why}")
                raise UrDaemonError(
                    f"cannot connect to {endpoint}: nothing answered within {timeout:g} s "
                    "(is the daemon running and listening there?)"
                )
            await asyncio.sleep(PEER_WAIT_S)
        return cls(session, loop, endpoint, holder=holder)

    async def __aenter__(self) -> Client:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Release every lease this client holds, stop background tasks, undeclare subscriptions and
        close the session."""
        for lease in list(self._leases.values()):
            with contextlib.suppress(UrDaemonError):
                await lease.release(timeout=RELEASE_ON_CLOSE_S)
        await super().close()

    async def robots(self, *, timeout: float = 2.0) -> list[tuple[str, str]]:
        """(cell, robot) of every robot served, from their liveliness tokens."""

        def ask() -> list[str]:
            return [
                str(r.ok.key_expr)
                for r in self.session.liveliness().get(ALIVE_ANYWHERE, timeout=timeout)
                if r.ok
            ]

        try:
            keys = await self._loop.run_in_executor(None, ask)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot list robots at {self.endpoint}: {zenoh_message(err)}") from err
        return sorted(found for found in map(CellKeys.of_alive, keys) if found is not None)

    async def robot(self, name: str, *, cell: str | None = None, timeout: float = 5.0) -> RobotClient:
        """A handle on robot ``name``; finds its cell from the liveliness tokens unless given.

        Raises ``NoSuchRobot`` (listing the robots served) when robots are served but none is
        ``name`` (in ``cell``) and the list stayed the same over ``STABLE_POLLS`` polls; waits up to
        ``timeout`` s while no robot at all is served, or while the list still grows (a daemon
        starting its robots one after the other: 8 robots on a busy machine take seconds).
        """
        deadline = self._loop.time() + timeout
        misses = 0
        seen: set[tuple[str, str]] = set()
        while True:
            served = await self.robots()
            cells = sorted({c for c, r in served if r == name and cell in (None, c)})
            if len(cells) == 1:
                keys = RobotKeys(cells[0], name)
                return RobotClient(self, keys, self.lease(keys))
            if len(cells) > 1:
                raise UrDaemonError(
                    f"robot {name!r} is served in several cells ({', '.join(cells)}); name one"
                )
            if served:
                grown = not seen.issuperset(served)
                seen.update(served)
                misses = 0 if grown else misses + 1  # tokens still arriving: keep waiting
                if misses >= STABLE_POLLS:
                    raise NoSuchRobot(_no_such_robot(name, cell, served, self.endpoint), served)
            if self._loop.time() > deadline:
                if served:
                    raise NoSuchRobot(_no_such_robot(name, cell, served, self.endpoint), served)
                raise UrTimeoutError(
                    f"no robot is served at {self.endpoint} (waited {timeout:g} s for {name!r})"
                )
            await asyncio.sleep(0.1)

    async def stop_cell(self, cell: str | None = None, *, timeout: float = QUERY_TIMEOUT_S) -> dict[str, Any]:
        """Stop every robot of ``cell`` at once (default: the one cell served); the reply names each
        robot's outcome (``{"ok": true, "robots": {"alice": {"ok": true}, ...}}``)."""
        if cell is None:
            cells = sorted({c for c, _ in await self.robots()})
            if len(cells) != 1:
                raise UrDaemonError(
                    f"{'no cell is' if not cells else 'several cells are'} served at {self.endpoint}"
                    + (f" ({', '.join(cells)}); name one" if cells else "")
                )
            cell = cells[0]
        return await self.request(CellKeys(cell).stop, timeout=timeout)

    async def robot_description(self, cell: str, *, timeout: float = QUERY_TIMEOUT_S) -> str:
        """The cell URDF."""
        replies = await self.query(CellKeys(cell).robot_description, timeout=timeout)
        if not replies:
            raise UrTimeoutError(f"no robot_description from cell {cell!r} at {self.endpoint}")
        return replies[0].decode()

    def lease(self, keys: RobotKeys) -> Lease:
        """This client's lease on the robot of ``keys`` (one per robot, whichever handle asks)."""
        lease = self._leases.get(keys.base)
        if lease is None:
            lease = self._leases[keys.base] = Lease(self, keys)
        return lease


def _config_file(config_file: str | None) -> Any:
    """The Zenoh config in ``config_file`` (None without one)."""
    if config_file is None:
        return None
    try:
        return zenoh.Config.from_file(config_file)
    except (zenoh.ZError, OSError) as err:
        reason = zenoh_message(err) if isinstance(err, zenoh.ZError) else (err.strerror or str(err))
        raise UrDaemonError(f"cannot read the Zenoh config {config_file}: {reason}") from err


def _file_endpoint(conf: Any) -> str | None:
    """The first endpoint a Zenoh config connects to (None: none, or no config)."""
    if conf is None:
        return None
    try:
        endpoints = json.loads(conf.get_json("connect/endpoints"))
    except (zenoh.ZError, ValueError):
        return None
    if isinstance(endpoints, dict):  # per mode: {"peer": [...], "client": [...]}
        endpoints = next((v for v in endpoints.values() if v), [])
    if isinstance(endpoints, list) and endpoints and isinstance(endpoints[0], str):
        return endpoints[0]
    return None


def _session_config(endpoint: str, low_latency: bool, base: Any) -> Any:
    """The client session's Zenoh config: ``base`` (a config file's, if any) as the base, then a peer
    with ``endpoint`` and no scouting, as ``zenoh_config`` makes it."""
    ours = zenoh_config("peer", [], [endpoint], low_latency=low_latency)
    if base is None:
        return ours
    keys = ["mode", "listen/endpoints", "connect/endpoints", "scouting/multicast/enabled"]
    if low_latency:
        keys += ["transport/unicast/lowlatency", "transport/unicast/qos/enabled"]
    for key in keys:
        base.insert_json5(key, ours.get_json(key))
    return base


def _has_peer(session: Any) -> bool:
    info = session.info
    return bool(list(info.peers_zid()) or list(info.routers_zid()))


def _no_such_robot(name: str, cell: str | None, served: Sequence[tuple[str, str]], endpoint: str) -> str:
    where = f"{cell}/{name}" if cell is not None else repr(name)
    listed = ", ".join(f"{c}/{r}" for c, r in served)
    return f"no robot {where} at {endpoint}; served: {listed}"
