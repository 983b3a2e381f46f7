"""The cell file's access grants as Zenoh's ``access_control`` rules on the exact keys of keys.py and the
services of services.py: default deny, both flows, one subject per identity (docs/security.md).

The access-control promise: the daemon's session drops every message no grant allows, in both
directions, on its own links; ``stop`` and finding the cell's robots pass for every connection,
whatever the grants say, so a stop is never refused to anyone who can reach the daemon at all.
The daemon's session gets these rules from session_config.py; a router's config can take them too
(docs/scale-out.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from urdaemon.cell.zenoh_options import ALL_ROBOTS, AccessOptions, Grant
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.services import SERVICES, STOP

__all__ = ["ANYONE", "ANY_CELL", "access_control"]

ANYONE = "urdaemon:anyone"
"""The Zenoh ACL subject every connection matches: it may stop robots and find the cell's robots (the
colon keeps it apart from the cell file's identity names)."""
ANY_CELL = "*"
"""The cell chunk of the access rules when the caller does not name the cell (session_config.py
``configure_daemon``)."""

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
