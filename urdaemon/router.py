"""``urdaemon router``: a Zenoh router that the daemons of several cells and their clients share.

Each daemon serves its cell as a Zenoh client of the router (cell file ``zenoh: {mode: client,
connect: [tcp/ROUTER:7447]}``); clients connect to the router as they would to one daemon, and reach
every cell's robots through it (docs/scale-out.md). The router is one Zenoh session in router mode,
opened with eclipse-zenoh's Python package (the same router as Eclipse's ``zenohd``, which is not
on the package registries). It holds no robot: it routes keys, so it needs no real-time care.

Configuration: ``--zenoh-config FILE`` (Zenoh JSON5: TLS, access control, router-to-router links)
as the base; then the mode is ``router``, multicast scouting is off (every link is named in some
``connect``), ``--listen`` and ``--connect`` replace the file's endpoints when given, and the admin
space is on (read-only unless the file says otherwise, as ``zenohd`` has it): the router reads back
where it actually listens there (a port 0 endpoint gets a port from the OS) and logs it.

Exit codes: 0 stopped by Ctrl-C, SIGTERM or SIGHUP; 1 the router could not open (a port taken, a
host name that does not resolve); 2 bad input (an endpoint, the config file).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import re
import sys
from collections.abc import Sequence
from typing import Any

from urdaemon.errors import ConfigError, UrDaemonError

__all__ = [
    "DEFAULT_LISTEN",
    "Router",
    "add_parsers",
    "endpoint_problem",
    "router_config",
    "run",
    "serve_router",
]

log = logging.getLogger(__name__)

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
"""Where the router listens by default: the daemon's default endpoint, so clients on this machine
(``urdaemon move``, ``Client.connect()``) reach it unchanged; other hosts need ``--listen``."""
_HOST_PORT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
"""Protocols whose address is HOST:PORT."""
_SECURE = ("tls", "quic")
LOCATOR_TIMEOUT_S = 2.0
"""How long the router waits for its own admin space to say where it listens."""


def add_parsers(sub: Any) -> None:
    """``router``: a Zenoh router for several cells (cli/parser.py ``TOOL_MODULES``)."""
    router = sub.add_parser(
        "router",
        help="run a Zenoh router that several cells' daemons (zenoh mode: client) and their clients "
        "connect to (docs/scale-out.md)",
    )
    router.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to accept sessions on (repeatable; default {DEFAULT_LISTEN}, or the "
        "--zenoh-config file's; port 0: any free port, logged)",
    )
    router.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="another router to link to (repeatable; default: the --zenoh-config file's, or none)",
    )
    router.add_argument(
        "--zenoh-config",
        metavar="FILE",
        default=None,
        help="Zenoh JSON5 config to start from (TLS, access control); the mode is always router",
    )
    router.set_defaults(run=run)


def endpoint_problem(endpoint: str) -> str | None:
    """Why ``endpoint`` cannot be listened on or dialled (None when it looks right): the protocol,
    and for ``tcp``/``udp``/``tls``/``quic``/``ws`` a host (IP address or name) and a port 0..65535."""
    from urdaemon.cell.schema_types import HOST_NAME_PATTERN
    from urdaemon.cell.zenoh_options import ENDPOINT_PATTERN

    example = "like tcp/127.0.0.1:7447"
    if not re.match(ENDPOINT_PATTERN, endpoint):
        return f"{endpoint!r} is not a Zenoh endpoint {example}"
    protocol, _, address = endpoint.partition("/")
    if protocol not in _HOST_PORT_PROTOCOLS:
        return None
    address = re.split(r"[?#]", address, maxsplit=1)[0]
    host, colon, port = address.rpartition(":")
    if not colon or not port.isdigit() or int(port) > 65535:
        return f"{endpoint!r} needs a port 0..65535 after the host ({example}; 0: any free port)"
    if host.startswith("[") and host.endswith("]"):
        return None if _is_ip(host[1:-1]) else f"{endpoint!r}: {host} is not an IPv6 address"
    if re.fullmatch(r"[\d.]+", host):
        return None if _is_ip(host) else f"{endpoint!r}: {host} is not an IPv4 address"
    if not re.match(HOST_NAME_PATTERN, host):
        return f"{endpoint!r}: {host!r} is not an IP address or host name"
    return None


def _is_ip(text: str) -> bool:
    import ipaddress

    try:
        ipaddress.ip_address(text)
    except ValueError:
        return False
    return True


def router_config(
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    config_file: str | None = None,
) -> Any:
    """The router's ``zenoh.Config``: ``config_file`` (if any) as the base, as the module says.

    Raises ``ConfigError`` naming what is wrong: an endpoint, the file, a ``tls/`` endpoint without
    the certificates to listen with.
    """
    import zenoh

    conf = _base_config(config_file)
    conf.insert_json5("mode", json.dumps("router"))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("adminspace/enabled", "true")
    for field, given in (("listen", listen), ("connect", connect)):
        source = f"--{field}" if given else f"{field} (in --zenoh-config)"
        endpoints = list(given) if given else _file_endpoints(conf, field)
        if field == "listen" and not endpoints:
            endpoints = [DEFAULT_LISTEN]
        for endpoint in endpoints:
            problem = endpoint_problem(endpoint)
            if problem is not None:
                raise ConfigError(f"{source} {problem}")
        try:
            conf.insert_json5(f"{field}/endpoints", json.dumps(endpoints))
        except zenoh.ZError as err:
            raise ConfigError(f"{source} {endpoints}: {_first_line(err)}") from None
    secure = [e for e in _file_endpoints(conf, "listen") if e.split("/", 1)[0] in _SECURE]
    if secure and json.loads(conf.get_json("transport/link/tls/listen_certificate")) is None:
        raise ConfigError(
            f"--listen {secure[0]} needs a certificate: set transport/link/tls (root_ca_certificate, "
            "listen_certificate, listen_private_key) in --zenoh-config (docs/scale-out.md)"
        )
    return conf


def _base_config(config_file: str | None) -> Any:
    import os

    import zenoh

    if config_file is None:
        return zenoh.Config()
    if not os.path.isfile(config_file):
        raise ConfigError(f"--zenoh-config {config_file!r} is not a file")
    try:
        return zenoh.Config.from_file(config_file)
    except zenoh.ZError as err:
        raise ConfigError(f"--zenoh-config {config_file}: {_first_line(err)}") from None


def _file_endpoints(conf: Any, field: str) -> list[str]:
    """The endpoints ``conf`` sets for ``field`` (none when it keeps Zenoh's per-mode defaults)."""
    value = json.loads(conf.get_json(f"{field}/endpoints"))
    return [str(e) for e in value] if isinstance(value, list) else []


def _first_line(err: BaseException) -> str:
    """Zenoh's message without the source location it appends (`` at /root/.cargo/...``)."""
    return re.split(r" at /\S+\.rs:\d+", str(err), maxsplit=1)[0].strip()


class Router:
    """One Zenoh session in router mode: listening once open, every link dropped on ``close``."""

    def __init__(self, session: Any, configured: Sequence[str]) -> None:
        self.session = session
        self._configured = list(configured)

    @classmethod
    async def open(cls, conf: Any) -> Router:
        """Open the router (a Zenoh session of ``router_config``'s config) off the event loop.

        Raises ``UrDaemonError`` when Zenoh cannot listen (a port taken, a host that does not resolve).
        """
        import zenoh

        configured = _file_endpoints(conf, "listen")
        try:
            session = await asyncio.get_running_loop().run_in_executor(None, zenoh.open, conf)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot open the router (listen {configured}): {_first_line(err)}") from None
        return cls(session, configured)

    @property
    def zid(self) -> str:
        """The router's Zenoh id."""
        return str(self.session.zid())

    async def locators(self, timeout: float = LOCATOR_TIMEOUT_S) -> list[str]:
        """Where the router listens, ports chosen by the OS included, from its own admin space
        (``@/<zid>/router``); the configured endpoints when the admin space does not answer."""

        def ask() -> list[str]:
            for reply in self.session.get(f"@/{self.zid}/router", timeout=timeout):
                if reply.ok is not None:
                    found = json.loads(reply.ok.payload.to_string()).get("locators")
                    if isinstance(found, list) and found:
                        return [str(locator) for locator in found]
            return []

        try:
            found = await asyncio.get_running_loop().run_in_executor(None, ask)
        except Exception as err:  # zenoh.ZError, or an admin space reply we cannot read
            log.debug("router: admin space unreadable: %s", err)
            found = []
        return found or list(self._configured)

    async def close(self) -> None:
        """Drop every link and close the session (off the event loop)."""
        await asyncio.get_running_loop().run_in_executor(None, self.session.close)

    async def __aenter__(self) -> Router:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


async def serve_router(conf: Any, stop: asyncio.Event) -> None:
    """Run the router of ``conf`` until ``stop`` is set, logging where it listens."""
    async with await Router.open(conf) as router:
        where = ", ".join(await router.locators())
        log.info("zenoh router %s listening on %s", router.zid, where)
        await stop.wait()
        log.info("zenoh router %s stopping", router.zid)


def run(args: argparse.Namespace) -> int:
    """``urdaemon router``: serve until Ctrl-C, SIGTERM or SIGHUP; the exit code."""
    from urdaemon.stop_signals import end_stop_signals, stop_on_signals, stop_signal_handlers

    try:
        conf = router_config(args.listen, args.connect, args.zenoh_config)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    async def main() -> None:
        stop = asyncio.Event()
        stop_on_signals(stop, "the zenoh router")
        await serve_router(conf, stop)

    # only ``urdaemon router`` itself owns its process; called otherwise, it gives the handlers back
    previous = None if getattr(args, "owns_process", False) else stop_signal_handlers()
    try:
        asyncio.run(main())
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    finally:
        end_stop_signals(previous)
    return 0
