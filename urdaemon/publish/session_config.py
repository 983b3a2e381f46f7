"""How urdaemon's Zenoh sessions are configured: any session's endpoints, scouting and transport
(``zenoh_config``), and the daemon's from the cell file's ``zenoh`` section (``serve_config``), with
its TLS and access control (``configure_daemon``, the rules from access.py)."""

from __future__ import annotations

import json
from typing import Any

import zenoh

from urdaemon.cell.zenoh_options import ZenohOptions
from urdaemon.errors import ConfigError
from urdaemon.publish.access import ANY_CELL, access_control

__all__ = ["configure_daemon", "serve_config", "zenoh_config"]


def zenoh_config(
    mode: str,
    listen: tuple[str, ...] | list[str],
    connect: tuple[str, ...] | list[str],
    *,
    multicast: bool = False,
    low_latency: bool = False,
) -> Any:
    """A ``zenoh.Config`` with explicit endpoints, multicast scouting and the low-latency transport
    (which needs QoS off) as given."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast))
    if low_latency:
        conf.insert_json5("transport/unicast/lowlatency", "true")
        conf.insert_json5("transport/unicast/qos/enabled", "false")
    return conf


TX_QUEUE_BATCHES = 16
"""Batches a link may queue per priority before a dropping publication is dropped (Zenoh's default
is 2, with 1 ms of waiting before the drop). Under CPU load a link's send thread regularly waits
longer than that, and 2 batches then lost 1-2 % of the state streams a recorder on another process
received; 16 lost none in the same runs (docs/operating.md, "Busy PCs"). Batches are allocated only
when used."""

QUEUED_PRIORITIES = ("real_time", "data")
"""The priorities the daemon publishes at: state streams (real time) and everything else (data)."""


def serve_config(options: ZenohOptions, listen: tuple[str, ...], cell: str | None = None) -> Any:
    """The daemon's session: the cell file's mode, endpoints, scouting and transport, without shared
    memory.

    Zenoh's shared memory moves a payload of 3 KiB or more to a peer on the same host through a
    16 MiB pool, mapped (and resident) from the first such message on: for the daemon, the first
    client asking for the URDF. Its messages are small JSON, so the pool bought nothing and cost a
    fifth of the process's memory; peers that use shared memory still connect, over the network
    transport (docs/performance.md, "The serve process"). ``cell``: the cell the access rules
    name (access.py); without it they name any cell.

    A daemon in ``client`` mode listens nowhere (the cell file refuses ``listen`` there), so a
    ``listen`` given anyway (``urdaemon serve --listen``) is refused: ``ConfigError``.
    """
    if options.mode == "client" and listen:
        raise ConfigError(
            f"the cell's zenoh mode is 'client' (it dials {list(options.connect)}) and accepts no sessions; "
            f"cannot listen on {list(listen)} (leave out --listen, or use mode 'peer')"
        )
    conf = zenoh_config(
        options.mode,
        listen,
        options.connect,
        multicast=options.multicast_scouting,
        low_latency=options.low_latency,
    )
    conf.insert_json5("transport/shared_memory/enabled", "false")
    for priority in QUEUED_PRIORITIES:
        conf.insert_json5(f"transport/link/tx/queue/size/{priority}", str(TX_QUEUE_BATCHES))
    configure_daemon(conf, options, cell)
    return conf


def configure_daemon(conf: Any, options: ZenohOptions, cell: str | None = None) -> None:
    """Add the cell file's TLS and access control settings to the daemon's ``zenoh.Config``.

    ``cell`` names the cell the access rules are written for; without it they name any cell
    (``*/alice/goal/move``), which on a daemon's own links means the same robots of its own cell.
    """
    if options.tls is not None:
        tls = options.tls
        for key, value in (
            ("root_ca_certificate", tls.root_ca),
            ("listen_certificate", tls.certificate),
            ("listen_private_key", tls.private_key),
            # the same identity when the daemon itself connects (zenoh.connect: tls/ routers)
            ("connect_certificate", tls.certificate),
            ("connect_private_key", tls.private_key),
            ("enable_mtls", tls.mutual),
        ):
            conf.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    if options.access is not None:
        conf.insert_json5("access_control", json.dumps(access_control(options.access, cell or ANY_CELL)))
