"""The cell file's access grants as Zenoh's ``access_control`` rules, derived from the endpoint table
(endpoints.py): each row's ``audience`` says which grants reach its key, its ``kind`` what a client
does there. Default deny, both flows, one subject per identity (docs/security.md).

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
from urdaemon.publish.endpoints import CELL_ENDPOINTS, ROBOT_ENDPOINTS, Audience, Endpoint, Kind
from urdaemon.publish.keys import ALIVE_ANYWHERE, CellKeys, RobotKeys

__all__ = ["ACTIONS", "ANYONE", "ANY_CELL", "access_control", "grant_key"]

ANYONE = "urdaemon:anyone"
"""The Zenoh ACL subject every connection matches: it may stop robots and find the cell's robots (the
colon keeps it apart from the cell file's identity names)."""
ANY_CELL = "*"
"""The cell chunk of the access rules when the caller does not name the cell (session_config.py
``configure_daemon``)."""

ACTIONS: dict[Kind, tuple[tuple[str, str], ...]] = {
    Kind.PUBLICATION: (("ingress", "declare_subscriber"), ("egress", "put")),
    Kind.QUERYABLE: (("ingress", "query"), ("egress", "reply"), ("egress", "declare_queryable")),
    Kind.SUBSCRIBER: (("ingress", "put"), ("egress", "declare_subscriber")),
    Kind.LIVELINESS: (
        ("ingress", "declare_liveliness_subscriber"),
        ("ingress", "liveliness_query"),
        ("egress", "liveliness_token"),
    ),
    Kind.TOKEN: (("ingress", "liveliness_token"),),
}
"""What a client does on a key of each kind, as Zenoh's (flow, message) pairs: it subscribes to a
publication, asks a queryable, puts on a subscriber, watches or asks for the daemon's liveliness
token, declares its own (the lease holder's)."""


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
    """Every connection may use the rows for anyone (``stop``: the robots' and the cell's), and find
    the cell's robots (their liveliness tokens, in any cell: what the client's discovery asks)."""
    any_robot, whole = RobotKeys(cell, "*"), CellKeys(cell)
    rules = _rules("anyone", ROBOT_ENDPOINTS, any_robot, Audience.ANYONE)
    rules += _rules("anyone: cell", CELL_ENDPOINTS, whole, Audience.ANYONE)
    # the daemon has only its own tokens: finding the robots shows nothing but their names
    rules.append(_Rule("find robots", ACTIONS[Kind.LIVELINESS], (ALIVE_ANYWHERE,)))
    return rules


def _grant_rules(grant: Grant, cell: str) -> list[_Rule]:
    """What one grant allows: reading its ``read`` and ``command`` robots, commanding its ``command``
    robots (a commander follows its goals, so it reads what it commands)."""
    rules: list[_Rule] = []
    whole = CellKeys(cell)
    readers = dict.fromkeys(grant.read + grant.command)
    for robot in readers:
        rules += _rules(f"read {robot}", ROBOT_ENDPOINTS, RobotKeys(cell, robot), Audience.READER)
    if readers:  # the cell's description and the daemon's, what any reader needs to draw its robots
        rules += _rules("read cell", CELL_ENDPOINTS, whole, Audience.READER)
    if ALL_ROBOTS in readers:  # every robot: the cell's tf (every link pose) and the cell goals' messages
        rules += _rules("read cell: every robot", CELL_ENDPOINTS, whole, Audience.CELL_READER)
    for robot in grant.command:
        rules += _rules(f"command {robot}", ROBOT_ENDPOINTS, RobotKeys(cell, robot), Audience.COMMANDER)
    if ALL_ROBOTS in grant.command:  # every robot: the cell goals
        rules += _rules("command cell", CELL_ENDPOINTS, whole, Audience.COMMANDER)
    return rules


def _rules(
    name: str, rows: Sequence[Endpoint], keys: RobotKeys | CellKeys, audience: Audience
) -> list[_Rule]:
    """One rule per kind of the rows for ``audience``: the actions a client takes on such a key."""
    keys_by_kind: dict[Kind, list[str]] = {}
    for row in rows:
        if row.audience is audience:
            keys_by_kind.setdefault(row.kind, []).append(grant_key(row, keys))
    return [
        _Rule(f"{name}: {kind}", ACTIONS[kind], tuple(dict.fromkeys(found)))
        for kind, found in keys_by_kind.items()
    ]


def grant_key(row: Endpoint, keys: RobotKeys | CellKeys) -> str:
    """The key a grant allows for ``row``: its own, but a commanding service's is every service
    (``service/*``): a commander may ask one the robot lacks, and hear which it has."""
    if row.service is not None and row.commanding and isinstance(keys, RobotKeys):
        return keys.service("*")
    return row.key(keys)
