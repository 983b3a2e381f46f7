"""The robot services are declared once (publish/services.py): the runtime's queryables and
``service_names``, the client's calls and waits, the CLI's help and docs/keys.md's rows all follow
from the one table (issue 15: adding a service touched six files).

No Zenoh: the runtime is declared on a recording node, the client sends through a recording session.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS
from tests.integration.test_review_planning import Query
from urdaemon.backends.base import Backend
from urdaemon.cell import parse_cell
from urdaemon.cli import main
from urdaemon.client import RobotClient
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell, make_backend
from urdaemon.errors import MessageError
from urdaemon.model import (
    CycleStatsRequest,
    DashboardRequest,
    ForceModeRequest,
    SetIoRequest,
    SetPayloadRequest,
    SetTcpRequest,
    SpeedSliderRequest,
    ToolVoltageRequest,
)
from urdaemon.publish import envelope, service_requests, services, stream_commands
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.tap import Matching
from urdaemon.robot import RobotRuntime

ROOT = Path(__file__).resolve().parents[2]


class RecordingNode:
    """The node's declaring API, recording the keys of queryables and subscribers."""

    def __init__(self) -> None:
        self.queryables: dict[str, Any] = {}
        self.subscribers: dict[str, Any] = {}

    def publisher(self, key: str, **_: Any) -> Any:
        return None

    def matching(self, publisher: Any) -> Matching:
        return Matching(False)

    def queryable(self, key: str, handler: Any, **_: Any) -> None:
        assert key not in self.queryables, f"{key} declared twice"
        self.queryables[key] = handler

    def subscriber(self, key: str, handler: Any, **_: Any) -> None:
        self.subscribers[key] = handler

    def liveliness_token(self, key: str) -> None:
        pass


TOKEN = b"0123456789abcdef0123456789abcdef"
"""The lease token ``HeldLease`` gives every command."""


class RecordingSession:
    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes]] = []
        self.put_attachments: list[bytes | None] = []

    def put(self, key: str, payload: bytes, *, attachment: bytes | None = None) -> None:
        self.puts.append((key, payload))
        self.put_attachments.append(attachment)


class HeldLease:
    """A command lease the recording client already holds (its acquire asks nothing)."""

    usable = True
    ended_reason: str | None = None
    refusal: str | None = None

    async def acquire(self, **_: Any) -> dict[str, Any]:
        return {"ok": True}

    def attachment(self) -> bytes:
        return TOKEN

    def end(self, reason: str) -> None:
        raise AssertionError(f"the recording client's lease never ends ({reason})")


class RecordingClient:
    """What ``RobotClient`` uses of its client's session: records each request (and its attachment:
    the lease's token on commanding services, none on the others) and answers ``ok``."""

    def __init__(self) -> None:
        self.session = RecordingSession()
        self.requests: list[tuple[str, dict[str, Any], float]] = []
        self.attachments: list[bytes | None] = []

    async def request(
        self, key: str, body: dict[str, Any] | None = None, *, timeout: float, attachment: bytes | None = None
    ) -> dict[str, Any]:
        self.requests.append((key, dict(body or {}), timeout))
        self.attachments.append(attachment)
        return {"ok": True}


def declared_runtime(text: str = TWO_MOCKS, name: str = "alice") -> tuple[RobotRuntime, RecordingNode]:
    """A robot's runtime declared on a recording node (its backend made as ``serve`` makes it)."""
    cell = parse_cell(text, base_dir=ROOT / "configs")
    limits = describe_cell(cell).limits[name]
    backend = make_backend(cell.robot(name), limits, None, cell.cell)
    node = RecordingNode()
    runtime = RobotRuntime(
        cell.cell,
        cell.robot(name),
        backend,
        MotionController(limits, period=backend.period),
        node,  # type: ignore[arg-type]
        cell.publish,
    )
    runtime.declare()
    return runtime, node


def test_the_runtime_answers_every_service_of_the_table_on_its_key() -> None:
    runtime, node = declared_runtime()
    assert runtime.service_names == frozenset(services.names())
    declared = {key for key in node.queryables if "/service/" in key}
    assert declared == {runtime.keys.service(name) for name in services.names()}


def test_the_freedrive_command_goes_where_the_runtime_listens() -> None:
    """The key was built by hand in client.py and robot.py; it is one RobotKeys property now."""
    runtime, node = declared_runtime()
    client = RecordingClient()
    RobotClient(client, runtime.keys, HeldLease()).freedrive(True)  # type: ignore[arg-type]
    [(key, payload)] = client.session.puts
    assert client.session.put_attachments == [TOKEN]
    assert key == runtime.keys.command_freedrive == "testcell/alice/command/freedrive"
    assert key in node.subscribers
    assert stream_commands.decode_freedrive(payload) is True


FORCE = ((0.0,) * 6, (0, 0, 1, 0, 0, 0), (0.0, 0.0, -5.0, 0.0, 0.0, 0.0), (0.1,) * 6)
CALLS: list[tuple[str, str, tuple[Any, ...], object]] = [
    ("set_io", "set_io", ("digital", 3, True), SetIoRequest("digital", 3, True)),
    ("set_io", "set_io", ("analog", 1, 0.25), SetIoRequest("analog", 1, 0.25)),
    ("set_payload", "set_payload", (2.0, (0.1, 0.0, -0.2)), SetPayloadRequest(2.0, (0.1, 0.0, -0.2))),
    ("set_payload", "set_payload", (1.5,), SetPayloadRequest(1.5)),
    ("set_speed_slider", "set_speed_slider", (0.5,), SpeedSliderRequest(0.5)),
    ("dashboard", "dashboard", ("power on",), DashboardRequest("power on")),
    ("set_tool_voltage", "set_tool_voltage", (24,), ToolVoltageRequest(24)),
    ("start_force_mode", "start_force_mode", FORCE, ForceModeRequest(*FORCE)),
    ("set_tcp", "set_tcp", ((0.0, 0.0, 0.1, 0.0, 0.0, 0.2),), SetTcpRequest((0.0, 0.0, 0.1, 0.0, 0.0, 0.2))),
    ("cycle_stats", "cycle_stats", (), CycleStatsRequest(False)),
    ("doctor", "doctor", (), None),
    ("startup", "startup", (), None),
    ("resend_program", "resend_program", (), None),
    ("hand_back_control", "hand_back_control", (), None),
    ("zero_ft_sensor", "zero_ft_sensor", (), None),
    ("end_force_mode", "end_force_mode", (), None),
    ("start_tool_contact", "start_tool_contact", (), None),
    ("end_tool_contact", "end_tool_contact", (), None),
    ("stop", "stop", (), None),
]


@pytest.mark.parametrize(("method", "name", "args", "expected"), CALLS)
async def test_each_named_client_call_sends_what_its_service_decodes(
    method: str, name: str, args: tuple[Any, ...], expected: object
) -> None:
    keys = RobotKeys("testcell", "alice")
    client = RecordingClient()
    await getattr(RobotClient(client, keys, HeldLease()), method)(*args)  # type: ignore[arg-type]
    [(key, body, timeout)] = client.requests
    entry = services.spec(name)
    assert key == keys.service(name)
    assert timeout == entry.timeout
    assert client.attachments == [TOKEN if entry.commanding else None]
    assert entry.decode(envelope.encode(body)) == expected


def test_every_named_service_has_a_client_call() -> None:
    assert {name for _, name, _, _ in CALLS} == set(services.names())


def test_the_client_waits_as_it_did_for_each_service() -> None:
    waits = {name: services.spec(name).timeout for name in services.names()}
    assert waits.pop("startup") == 60.0
    assert waits.pop("dashboard") == 30.0
    assert waits.pop("doctor") == 15.0
    assert set(waits.values()) == {5.0}


@pytest.mark.parametrize("name", [entry.name for entry in services.SERVICES if entry.request is None])
def test_a_service_without_arguments_refuses_garbage_naming_it(name: str) -> None:
    decode = services.spec(name).decode
    for nothing in (None, b"", b"{}", b'{"v": 1}'):
        assert decode(nothing) is None
    with pytest.raises(MessageError, match=rf"^{name} takes no arguments, but got: unknown field\(s\) now$"):
        decode(b'{"now": 1}')


def test_stop_is_never_refused_for_its_payload() -> None:
    for anything in (None, b"", b"garbage", b'{"now": 1}'):
        assert services.STOP.decode(anything) is None


def test_every_service_names_a_backend_method_it_needs() -> None:
    needs = {entry.name: entry.needs for entry in (*services.SERVICES, services.STOP)}
    for name, method in needs.items():
        assert method is None or callable(getattr(Backend, method, None)), name


def test_a_request_is_sent_with_the_message_field_names() -> None:
    body = service_requests.request_body(ForceModeRequest(*FORCE))
    assert body["type"] == 2
    assert "force_type" not in body
    assert body["selection"] == [0, 0, 1, 0, 0, 0]
    assert service_requests.request_body(None) == {}


def test_docs_list_the_services_as_the_table_declares_them() -> None:
    doc = (ROOT / "docs" / "keys.md").read_text(encoding="utf-8")
    queryables = doc.split("\n## Queryables", 1)[1].split("\n## ", 1)[0]  # endpoints.py's table follows
    rows = [line for line in queryables.splitlines() if line.startswith("| `<cell>/<robot>/service/")]
    assert rows == services.markdown_rows()


def test_the_cli_lists_every_service_with_its_request(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["service", "-h"])
    assert exit_info.value.code == 0
    shown = capsys.readouterr().out
    for entry in (*services.SERVICES, services.STOP):
        assert f"  {entry.name}: {entry.summary} (" in shown
    assert (
        "start_force_mode: start force mode (URScript force_mode semantics) (request: task_frame, " in shown
    )
    assert "type? (default 2)" in shown


REQUESTS: dict[str, dict[str, Any] | None] = {
    "set_io": {"kind": "digital", "pin": 1, "value": True},
    "set_payload": {"mass": 1.0},
    "set_speed_slider": {"fraction": 0.5},
    "dashboard": {"command": "robotmode"},
    "set_tool_voltage": {"volts": 12},
    "start_force_mode": {
        "task_frame": [0.0] * 6,
        "selection": [0, 0, 1, 0, 0, 0],
        "wrench": [0.0, 0.0, -5.0, 0.0, 0.0, 0.0],
        "limits": [0.1] * 6,
    },
    "cycle_stats": {"reset": False},
    "set_tcp": {"pose": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]},
}
"""A valid request of every service with arguments (the others get none)."""
MOCK_REFUSALS = {
    "dashboard": "mock backend has no dashboard server",
    "resend_program": "mock backend runs no control program",
    "hand_back_control": "mock backend runs no control program",
    "start_force_mode": "the mock backend has no force mode",
    "end_force_mode": "the mock backend has no force mode",
    "start_tool_contact": "the mock backend has no tool contact detection",
    "end_tool_contact": "the mock backend has no tool contact detection",
}
SERVO_REFUSALS = {
    **{name: reason.replace("mock", "servo") for name, reason in MOCK_REFUSALS.items()},
    "set_io": "servo backend has no IO outputs",
    "set_payload": "servo backend has no payload setting",
}
SERVO_ARM = (ROOT / "configs" / "servo_arm.yaml").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("text", "robot", "refusals"), [(TWO_MOCKS, "alice", MOCK_REFUSALS), (SERVO_ARM, "arm", SERVO_REFUSALS)]
)
async def test_each_backend_answers_every_service_its_own_way(
    text: str, robot: str, refusals: dict[str, str]
) -> None:
    """Every robot answers every service of the table; a backend without what a service needs refuses
    it with its own reason (backends/base.py, servo.py), and nothing else changes that answer."""
    runtime, node = declared_runtime(text, robot)
    answers = {}
    for name in services.names():
        query = Query(runtime.keys.service(name), REQUESTS.get(name))
        node.queryables[runtime.keys.service(name)](query)
        answers[name] = await query.answer(timeout=10.0)
    refused = {name: answer["reason"] for name, answer in answers.items() if not answer["ok"]}
    assert refused == refusals
    assert answers["cycle_stats"]["turnaround"]["count"] == 0
    assert {c["name"]: c["verdict"] for c in answers["doctor"]["checks"]}["controller"] == "n/a"
