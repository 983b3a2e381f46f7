"""The endpoint table (publish/endpoints.py) is the one declaration of every key: the runtime declares
each row with the row's settings, the access rules of a grant are the rows' audiences, and docs/keys.md
shows the table and names no key it lacks (issue 31: the Zenoh boundary declared once)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS
from urdaemon.cell import parse_cell
from urdaemon.cell.robot_options import READ_ONLY_REASON
from urdaemon.cell.zenoh_options import AccessOptions
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell, make_backend
from urdaemon.publish import endpoints, services
from urdaemon.publish.access import ACTIONS, ANYONE, access_control, grant_key
from urdaemon.publish.endpoints import (
    CELL,
    CELL_ENDPOINTS,
    ROBOT,
    ROBOT_ENDPOINTS,
    Audience,
    Endpoint,
    Kind,
    ReadOnly,
    ReadOnlyGuard,
    declare_endpoints,
)
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.robot import RobotRuntime

ROOT = Path(__file__).resolve().parents[2]
KEYS_MD = (ROOT / "docs" / "keys.md").read_text(encoding="utf-8")


def test_docs_show_the_table_as_it_is_declared() -> None:
    section = KEYS_MD.split("\n## Every endpoint at a glance", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| `<cell>")]
    assert rows == endpoints.markdown_rows()


def _documented_keys() -> set[str]:
    """Every key the tables of docs/keys.md list before the generated one (first column)."""
    before = KEYS_MD.split("\n## Every endpoint at a glance", 1)[0]
    after = KEYS_MD.split("\n## Subscribed", 1)[1]
    return {
        match.group(1)
        for text in (before, after)
        for match in re.finditer(r"^\| `(<cell>/[^`]*)` \|", text, flags=re.MULTILINE)
    }


def test_the_hand_written_tables_name_only_keys_of_the_table_and_every_one() -> None:
    """Drift either way fails: a key documented that no row declares, or a row no table documents
    (but for the two a client never addresses: the cell's catch-all queryable and the holders' tokens,
    which "The command lease" describes)."""
    patterns = set()
    for row in (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS):
        kinds = ("feedback", "result") if row is ROBOT.goal_messages else ("result",)
        patterns |= {row.pattern.replace("<kind>", kind) for kind in kinds}
    undocumented = {CELL.any_robot.pattern, ROBOT.lease_holder.pattern}
    assert _documented_keys() == patterns - undocumented


def test_each_row_is_consistent() -> None:
    """The rules the columns follow: only a commanding row needs the lease or is refused by a
    read-only robot; a reply field only on a queryable; ``any_id`` only on a key with a ``*``."""
    for row in (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS):
        if row.lease or row.read_only is not ReadOnly.SERVED:
            assert row.commanding, row.name
        if row.answer is not None or row.any_id:
            assert row.kind is Kind.QUERYABLE, row.name
        key = row.key(CellKeys("c") if row.cell_level else RobotKeys("c", "r"))
        if row.kind is Kind.QUERYABLE and row is not CELL.any_robot:
            assert row.any_id == ("*" in key), row.name
        if row.kind is Kind.SUBSCRIBER:
            assert row.max_bytes is not None, row.name
    assert len({row.pattern for row in (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS)}) == len(ROBOT_ENDPOINTS) + len(
        CELL_ENDPOINTS
    )
    assert ROBOT_ENDPOINTS[-1] is ROBOT.alive, "the liveliness token is declared last"


def test_each_row_names_its_key_as_keys_py_makes_it() -> None:
    keys, cell = RobotKeys("c", "r"), CellKeys("c")
    for row in ROBOT_ENDPOINTS:
        if row.service is not None:
            assert row.key(keys) == keys.service(row.service.name)
        elif row is not ROBOT.lease_holder:
            assert row.key(keys) == getattr(keys, row.name)
    for row in CELL_ENDPOINTS:
        assert row.key(cell) == getattr(cell, row.name)


def test_the_services_are_the_service_tables_rows() -> None:
    rows = [row for row in ROBOT_ENDPOINTS if row.service is not None]
    assert [row.service.name for row in rows if row.service] == list(services.names())
    for row in rows:
        spec = row.service
        assert spec is not None
        if spec is services.STOP:
            assert (row.audience, row.max_bytes, row.lease) == (Audience.ANYONE, None, False)
            continue
        assert row.commanding == row.lease == spec.commanding
        assert row.message is spec.request
    assert ROBOT.service("dashboard").read_only is ReadOnly.BY_REQUEST
    assert ROBOT.service("cycle_stats").read_only is ReadOnly.SERVED
    assert ROBOT.service("set_io").read_only is ReadOnly.REFUSED


class _Recording:
    """A node that records what each declaration asked for."""

    def __init__(self) -> None:
        self.declared: dict[str, tuple[str, dict[str, Any]]] = {}

    def publisher(self, key: str, **settings: Any) -> str:
        self.declared[key] = ("publication", settings)
        return f"publisher {key}"

    def queryable(self, key: str, handler: Any, **settings: Any) -> None:
        self.declared[key] = ("queryable", {**settings, "handler": handler})

    def cell_queryable(self, key: str, handler: Any) -> None:
        self.declared[key] = ("queryable", {"handler": handler})

    def subscriber(self, key: str, handler: Any, **settings: Any) -> None:
        self.declared[key] = ("subscriber", {**settings, "handler": handler})

    def liveliness_token(self, key: str) -> None:
        self.declared[key] = ("liveliness", {})

    def matching(self, publisher: Any) -> Any:
        from urdaemon.publish.tap import Matching

        return Matching(False)


class _Lease:
    def refusal(self, attachment: bytes | None) -> str | None:
        return "lease: no"


@pytest.mark.parametrize("read_only", [None, READ_ONLY_REASON])
def test_every_row_is_declared_with_its_settings(read_only: str | None) -> None:
    """``declare_endpoints`` gives each row its key, size limit, reply field and check: the lease's
    guard on a leased row, a read-only robot's refusal on a refused one."""
    node, keys, lease = _Recording(), RobotKeys("c", "r"), _Lease()
    served = {
        row: None if row.kind in (Kind.PUBLICATION, Kind.LIVELINESS) else (lambda *_: None)
        for row in ROBOT_ENDPOINTS
        if row.kind is not Kind.TOKEN
    }
    declared = declare_endpoints(node, keys, served, guard=lease, read_only=read_only)
    assert list(node.declared) == [row.key(keys) for row in served]
    for row in served:
        kind, settings = node.declared[row.key(keys)]
        assert kind == str(row.kind)
        if row.kind is Kind.PUBLICATION:
            assert declared[row] == f"publisher {row.key(keys)}"
            assert settings.get("realtime", False) == row.realtime
            continue
        if row.kind in (Kind.QUERYABLE, Kind.SUBSCRIBER):
            assert settings["max_bytes"] == row.max_bytes
            guard = settings["guard"]
            if read_only is not None and row.read_only is ReadOnly.REFUSED:
                assert isinstance(guard, ReadOnlyGuard)
                assert guard.refusal(b"t") == READ_ONLY_REASON
            else:
                assert guard is (lease if row.lease else None), row.name
        if row.kind is Kind.QUERYABLE:
            assert (settings["answer"], settings["any_id"]) == (row.answer, row.any_id)
            wrapped = read_only is not None and row.read_only is ReadOnly.BY_REQUEST
            assert (settings["handler"] is not served[row]) == wrapped, row.name


def test_a_row_of_another_scope_is_refused() -> None:
    with pytest.raises(ValueError, match="not rows of the cell"):
        declare_endpoints(_Recording(), CellKeys("c"), {ROBOT.status: None})


def test_the_runtime_declares_every_robot_row_but_the_backends() -> None:
    """A mock robot's runtime serves every row but servo_command (a servo backend's publisher) and
    the holders' tokens (watched for the cell), each on the key the table says."""
    cell = parse_cell(TWO_MOCKS, base_dir=ROOT / "configs")
    limits = describe_cell(cell).limits["alice"]
    backend = make_backend(cell.robot("alice"), limits, None, cell.cell)
    node = _Recording()
    controller = MotionController(limits, period=backend.period)
    robot = cell.robot("alice")
    runtime = RobotRuntime(cell.cell, robot, backend, controller, node, cell.publish)  # type: ignore[arg-type]
    runtime.declare()
    declared = set(node.declared)
    elsewhere = {ROBOT.servo_command, ROBOT.lease_holder, ROBOT.goal_messages}  # goal messages: put per goal
    if not runtime.tcp_poses.available:  # no kinematics given: no tcp_pose
        elsewhere.add(ROBOT.tcp_pose)
    expected = {row.key(runtime.keys) for row in ROBOT_ENDPOINTS if row not in elsewhere}
    assert declared == expected


def _allowed(acl: dict[str, Any], subject: str, flow: str, message: str) -> set[str]:
    policies = [p for p in acl["policies"] if subject in p["subjects"]]
    rule_ids = {r for p in policies for r in p["rules"]}
    return {
        key
        for rule in acl["rules"]
        if rule["id"] in rule_ids and flow in rule["flows"] and message in rule["messages"]
        for key in rule["key_exprs"]
    }


ACCESS = AccessOptions.model_validate(
    {
        "identities": {
            "viewer": {"interfaces": ["lo"]},
            "operator": {"interfaces": ["eth0"]},
            "chief": {"interfaces": ["eth1"]},
        },
        "grants": [
            {"identities": ["viewer"], "read": ["alice"]},
            {"identities": ["operator"], "command": ["alice"]},
            {"identities": ["chief"], "command": ["*"]},
        ],
    }
)


def _reaches(row: Endpoint, subject: str) -> bool:
    """Whether the row's audience says ``subject`` (of ``ACCESS``) may use it, for robot alice."""
    audience = row.audience
    if audience is Audience.ANYONE:
        return True
    if subject == ANYONE or audience is Audience.NOBODY:
        return False
    if row.cell_level and audience in (Audience.CELL_READER, Audience.COMMANDER):
        return subject == "chief"  # a grant on every robot
    return audience is Audience.READER or subject != "viewer"


@pytest.mark.parametrize("subject", ["viewer", "operator", "chief", ANYONE])
def test_the_access_rules_allow_exactly_what_each_row_says(subject: str) -> None:
    """For every row and every action a client takes on its kind of key: allowed to the identities its
    audience names, denied to the others (robot alice, in cell ``c``)."""
    acl = access_control(ACCESS, "c")
    for row in (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS):
        keys: RobotKeys | CellKeys = CellKeys("c") if row.cell_level else RobotKeys("c", "alice")
        star: RobotKeys | CellKeys = CellKeys("c") if row.cell_level else RobotKeys("c", "*")
        for flow, message in ACTIONS[row.kind]:
            allowed = _allowed(acl, subject, flow, message) | _allowed(acl, ANYONE, flow, message)
            reached = grant_key(row, keys) in allowed or grant_key(row, star) in allowed
            assert reached == _reaches(row, subject), (row.name, subject, flow, message)
