"""Zenoh transport security from the cell file: TLS, mutual TLS and access control (docs/security.md).

``configure_daemon`` adds what the cell file's ``zenoh`` section asks for to the daemon's session
config (publish/node.py ``serve_config``); nothing when the cell file asks for none. ``access_control``
turns the cell file's grants ("viewer reads alice", "operator commands alice") into Zenoh's
``access_control`` rules on the exact keys of publish/keys.py. ``client_config`` and
``write_client_config`` make the Zenoh config a client connects with (``urdaemon client-config``).

The access-control promise: the daemon's session drops every message no grant allows, in both
directions, on its own links; ``stop`` and finding the cell's robots pass for every connection,
whatever the grants say, so a stop is never refused to anyone who can reach the daemon at all.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.cell.config import Cell
from urdaemon.cell.zenoh_options import ALL_ROBOTS, SECURE_PROTOCOLS, AccessOptions, Grant, ZenohOptions
from urdaemon.errors import ConfigError
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.services import SERVICES, STOP

__all__ = [
    "ANYONE",
    "access_control",
    "add_client_config_arguments",
    "client_config",
    "client_config_command",
    "client_config_main",
    "configure_daemon",
    "write_client_config",
]

ANYONE = "urdaemon:anyone"
"""The Zenoh ACL subject every connection matches: it may stop robots and find the cell's robots (the
colon keeps it apart from the cell file's identity names)."""
ANY_CELL = "*"
"""The cell chunk of the access rules when the caller does not name the cell (see ``configure_daemon``)."""

_SUBSCRIBE = (("ingress", "declare_subscriber"), ("egress", "put"))
"""A client subscribes to keys the daemon publishes on."""
_GET = (("ingress", "query"), ("egress", "reply"), ("egress", "declare_queryable"))
"""A client asks a queryable of the daemon."""
_PUT = (("ingress", "put"), ("egress", "declare_subscriber"))
"""A client publishes on keys the daemon subscribes to."""
_WATCH = (
    ("ingress", "declare_liveliness_subscriber"),
    ("ingress", "liveliness_query"),
    ("egress", "liveliness_token"),
)
"""A client watches or asks for the daemon's liveliness tokens."""
_HOLD = (("ingress", "liveliness_token"),)
"""A client declares a liveliness token (the lease holder's)."""


@dataclass(frozen=True, slots=True)
class _Rule:
    """One Zenoh ACL rule: these (flow, message) pairs on these keys are allowed."""

    id: str
    actions: tuple[tuple[str, str], ...]
    keys: tuple[str, ...]

    def entries(self) -> list[dict[str, Any]]:
        """Zenoh's rule entries: one per flow, each with its messages."""
        flows = sorted({flow for flow, _ in self.actions})
        return [
            {
                "id": f"{self.id}/{flow}",
                "permission": "allow",
                "flows": [flow],
                "messages": [message for f, message in self.actions if f == flow],
                "key_exprs": list(self.keys),
            }
            for flow in flows
        ]


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


def access_control(access: AccessOptions, cell: str) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the cell file's ``access``: default deny, one subject
    per identity, the rules each grant expands to, and ``stop`` and discovery for every connection."""
    rules: dict[str, _Rule] = {}
    policies: list[dict[str, Any]] = []
    anyone = _anyone_rules(cell)
    rules.update((rule.id, rule) for rule in anyone)
    policies.append({"id": "anyone", "rules": _entry_ids(anyone), "subjects": [ANYONE]})
    for i, grant in enumerate(access.grants):
        granted = _grant_rules(grant, cell)
        rules.update((rule.id, rule) for rule in granted)
        policies.append(
            {"id": f"grants[{i}]", "rules": _entry_ids(granted), "subjects": list(grant.identities)}
        )
    subjects: list[dict[str, Any]] = [{"id": ANYONE}]  # no property: matches every link
    for name, identity in access.identities.items():
        subject: dict[str, Any] = {"id": name}
        if identity.cert_common_names is not None:
            subject["cert_common_names"] = list(identity.cert_common_names)
        if identity.interfaces is not None:
            subject["interfaces"] = list(identity.interfaces)
        subjects.append(subject)
    return {
        "enabled": True,
        "default_permission": access.default,
        "rules": [entry for rule in rules.values() for entry in rule.entries()],
        "subjects": subjects,
        "policies": policies,
    }


def _entry_ids(rules: Sequence[_Rule]) -> list[str]:
    return [entry["id"] for rule in rules for entry in rule.entries()]


def _anyone_rules(cell: str) -> list[_Rule]:
    """Every connection may stop any robot or the cell, and find the cell's robots (their names)."""
    any_robot = RobotKeys(cell, "*")
    return [
        _Rule("stop", _GET, (any_robot.service(STOP.name), CellKeys(cell).stop)),
        # the client's discovery asks ``*/*/alive`` (client.py): the daemon has only its own tokens
        _Rule("find robots", _WATCH, ("*/*/alive",)),
    ]


def _grant_rules(grant: Grant, cell: str) -> list[_Rule]:
    """What one grant allows: reading its ``read`` and ``command`` robots, commanding its ``command``
    robots (a commander follows its goals, so it reads what it commands)."""
    rules: list[_Rule] = []
    for robot in dict.fromkeys(grant.read + grant.command):
        rules += _read_rules(cell, robot)
    for robot in grant.command:
        rules += _command_rules(cell, robot)
    return rules


def _read_rules(cell: str, robot: str) -> list[_Rule]:
    """Subscribing to a robot's state, events and goal messages; asking for goal results, the
    services that only read (``cycle_stats``, ``doctor``), the cell's description (static: what any
    reader needs to draw the robot) and the daemon's description of itself (``daemon``: what
    ``urdaemon list`` and ``info`` read). ``*``: every robot, the cell's tf (every robot's link poses)
    and the cell goals' messages."""
    keys, whole = RobotKeys(cell, robot), CellKeys(cell)
    readable = tuple(keys.service(s.name) for s in SERVICES if not s.commanding and s is not STOP)
    state = (keys.joint_states, keys.tcp_pose, keys.status, keys.io, keys.events, keys.servo_command)
    rules = [
        _Rule(f"read {robot}: state", _SUBSCRIBE, (*state, keys.goal_messages)),
        _Rule(
            f"read {robot}: queries",
            _GET,
            (keys.goal_results, *readable, whole.robot_description, whole.daemon),
        ),
        _Rule(f"read {robot}: alive", _WATCH, (keys.alive,)),
    ]
    if robot == ALL_ROBOTS:
        rules += [
            _Rule("read cell: state", _SUBSCRIBE, (whole.tf, whole.goal_messages)),
            _Rule("read cell: queries", _GET, (whole.goal_results,)),
        ]
    return rules


def _command_rules(cell: str, robot: str) -> list[_Rule]:
    """Everything a commander of ``robot`` sends: goals, cancel, every service, the lease and its
    liveliness token, the command streams. ``*``: every robot, and cell goals."""
    keys = RobotKeys(cell, robot)
    queries = (
        keys.goal_trajectory,
        keys.goal_move,
        keys.goal_linear,
        keys.goal_cancel,
        keys.service("*"),
        keys.lease,
    )
    streams = (
        keys.command_joint_position,
        keys.command_joint_velocity,
        keys.command_twist,
        keys.command_freedrive,
    )
    rules = [
        _Rule(f"command {robot}: queries", _GET, queries),
        _Rule(f"command {robot}: streams", _PUT, streams),
        _Rule(f"command {robot}: lease token", _HOLD, (keys.lease_holder("*"),)),
    ]
    if robot == ALL_ROBOTS:
        whole = CellKeys(cell)
        rules.append(_Rule("command cell: goals", _GET, (whole.goal_trajectory, whole.goal_cancel)))
    return rules


def client_config(
    cell: Cell, *, certificate: str | None, private_key: str | None, endpoint: str | None = None
) -> dict[str, Any]:
    """A client's Zenoh config for ``cell``'s daemon: client mode on the daemon's ``tls/`` endpoint,
    the cell's root CA, and (mutual TLS) the client's certificate and key. Paths become absolute."""
    tls = cell.zenoh.tls
    if tls is None:
        raise ConfigError(f"cell {cell.cell!r}: zenoh.tls is not set: the daemon does not use TLS")
    if tls.mutual and (certificate is None or private_key is None):
        raise ConfigError("the daemon asks for mutual TLS: give the client's certificate and private key")
    endpoint = endpoint or _dialable(cell)
    if not endpoint.startswith(SECURE_PROTOCOLS):
        raise ConfigError(f"endpoint {endpoint}: a TLS client needs a tls/ or quic/ endpoint")
    link: dict[str, Any] = {"root_ca_certificate": _existing(tls.root_ca, "root CA")}
    if certificate is not None and private_key is not None:
        link["connect_certificate"] = _existing(certificate, "certificate")
        link["connect_private_key"] = _existing(private_key, "private key")
        link["enable_mtls"] = True
    return {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": link}},
    }


def _dialable(cell: Cell) -> str:
    """The daemon's first secure listen endpoint, if a client can dial its address as written."""
    for endpoint in cell.zenoh.listen:
        if endpoint.startswith(SECURE_PROTOCOLS):
            host = endpoint.split("/", 1)[1].rsplit(":", 1)[0].strip("[]")
            if host in ("0.0.0.0", "::"):
                raise ConfigError(
                    f"zenoh.listen: {endpoint} listens on every interface; give the endpoint clients "
                    "dial (--endpoint tls/HOST:PORT, HOST as in the daemon's certificate)"
                )
            return endpoint
    raise ConfigError("zenoh.listen has no tls/ endpoint; give the one clients dial (--endpoint)")


def _existing(path: str, what: str) -> str:
    resolved = Path(path).expanduser().resolve()
    if not resolved.is_file():
        raise ConfigError(f"{what} file not found: {resolved}")
    return str(resolved)


def write_client_config(
    cell: Cell,
    *,
    certificate: str | None,
    private_key: str | None,
    path: str | Path,
    endpoint: str | None = None,
) -> Path:
    """Write :func:`client_config` to ``path`` as JSON5 (plain JSON) readable by its owner only: it
    names the client's private key. Returns the path."""
    text = json.dumps(
        client_config(cell, certificate=certificate, private_key=private_key, endpoint=endpoint), indent=2
    )
    path = Path(path)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        out.write(text + "\n")
    return path


def add_client_config_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``urdaemon client-config``."""
    parser.add_argument("--config", required=True, help="the daemon's cell file (YAML)")
    parser.add_argument("--certificate", default=None, help="the client's certificate (PEM), for mTLS")
    parser.add_argument("--private-key", default=None, help="the client's private key (PEM), for mTLS")
    parser.add_argument(
        "--endpoint", default=None, help="the daemon's endpoint as clients dial it (default: its tls/ listen)"
    )
    parser.add_argument("--output", required=True, help="Zenoh config file to write (JSON5)")


def client_config_command(args: argparse.Namespace) -> int:
    """Run ``urdaemon client-config`` with parsed arguments; 0 on success, 2 on bad input."""
    from urdaemon.cell import load_cell

    try:
        cell = load_cell(args.config)
        path = write_client_config(
            cell,
            certificate=args.certificate,
            private_key=args.private_key,
            path=args.output,
            endpoint=args.endpoint,
        )
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"error: cannot write {args.output}: {err.strerror or err}", file=sys.stderr)
        return 2
    print(f"wrote {path}: connect with --zenoh-config {path} (Client.connect(config_file=...))")
    return 0


def client_config_main(argv: Sequence[str] | None = None) -> int:
    """``urdaemon client-config`` as a function of its arguments (without the command name)."""
    parser = argparse.ArgumentParser(
        prog="urdaemon client-config", description="write a client's Zenoh config for a TLS cell"
    )
    add_client_config_arguments(parser)
    return client_config_command(parser.parse_args(sys.argv[1:] if argv is None else list(argv)))
