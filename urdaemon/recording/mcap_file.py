"""An MCAP file of what a cell published: channels as ``channels.py`` declares them, written with the
``mcap`` library (no container format by hand).

``RecordingWriter`` takes each published message as it arrived (key, payload, when it arrived) and
writes it on its kind's channel, registered on first use; log and publish time are the message's own
``host_time_ns``. The cell URDF goes in twice: as the ``robot_description.urdf`` attachment and as
one ``std_msgs/msg/String`` on ``/robot_description``; the cell's tf goes in as one transform per
URDF joint, as Foxglove draws it beside the URDF (``channels.tf_record``). Not thread-safe: one writer thread.

``read_recording`` reads a file back in log-time order, each message as the daemon published it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import IO, Any

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from urdaemon import __version__
from urdaemon.recording import cdr
from urdaemon.recording.channels import (
    DESCRIPTION_TOPIC,
    KINDS,
    ROBOT_DESCRIPTION,
    Kind,
    Schema,
    kind_of,
    record_bytes,
    time_of,
)
from urdaemon.recording.tf_tree import joint_links

__all__ = ["URDF_ATTACHMENT", "Recorded", "RecordingWriter", "key_of", "read_recording"]

URDF_ATTACHMENT = "robot_description.urdf"
PROFILE = "ros2"
"""The file's MCAP profile when it holds only ROS 2 channels (``ros2_only``); else none."""


@dataclass(slots=True)
class _Counts:
    written: dict[str, int] = field(default_factory=dict)
    """Messages written, by topic."""
    skipped: int = 0
    """Messages of keys the recorder does not keep, or not JSON objects."""
    malformed: dict[str, str] = field(default_factory=dict)
    """The first problem seen on each key whose messages could not be converted."""


class RecordingWriter:
    """Writes published messages into an MCAP file (``finish`` writes its summary and index)."""

    def __init__(
        self,
        output: IO[bytes],
        *,
        cell: str | None = None,
        urdf: str | None = None,
        metadata: dict[str, str] | None = None,
        ros2_only: bool = False,
        chunk_size: int = 1 << 20,
    ) -> None:
        self._writer = Writer(output, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE if ros2_only else "", library=f"urdaemon {__version__}")
        self._ros2_only = ros2_only
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._cell = cell
        self._urdf = urdf
        self._urdf_written = False
        self._joints = joint_links(urdf) if urdf else ()
        self.counts = _Counts()
        info = {"urdaemon": __version__, "cell": cell or "", "created_ns": str(time.time_ns())}
        self._writer.add_metadata("urdaemon", {**info, **(metadata or {})})

    def add(self, key: str, payload: bytes, receive_ns: int) -> bool:
        """Write one published message; False when it is not kept (an unknown key, not JSON, or a
        message its channel's type cannot hold: counted, the first problem per key kept)."""
        where = kind_of(key)
        if where is None or (self._ros2_only and not where.kind.is_ros2):
            self.counts.skipped += 1
            return False
        try:
            message = json.loads(payload)
            if not isinstance(message, dict):
                raise ValueError("not a JSON object")
            data = record_bytes(where.kind, message, payload, key, self._joints)
        except (ValueError, KeyError, TypeError) as err:
            self.counts.malformed.setdefault(key, f"{type(err).__name__}: {err}")
            return False
        log_time = time_of(message, receive_ns)
        self._urdf_once(where.cell, log_time)
        self._write(where.topic, where.kind.schema, where.kind.message_encoding, data, log_time)
        return True

    def flush(self) -> None:
        """End the chunk in progress and hand everything to the output (a reader of a file cut short
        later finds every message added so far: ``recover.py``)."""
        self._writer.flush()  # type: ignore[no-untyped-call]

    def finish(self) -> None:
        """Write the summary and the index; the file is complete."""
        self._writer.finish()  # type: ignore[no-untyped-call]

    def _urdf_once(self, cell: str, log_time: int) -> None:
        if self._urdf_written or self._urdf is None:
            return
        self._urdf_written = True
        data = self._urdf.encode()
        self._writer.add_attachment(log_time, log_time, URDF_ATTACHMENT, "application/xml", data)
        self._write(DESCRIPTION_TOPIC, ROBOT_DESCRIPTION, "cdr", cdr.encode_string(self._urdf), log_time)

    def _write(self, topic: str, schema: Schema, encoding: str, data: bytes, log_time: int) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            schema_id = self._schemas.get(schema.name)
            if schema_id is None:
                schema_id = self._writer.register_schema(schema.name, schema.encoding, schema.data)
                self._schemas[schema.name] = schema_id
            channel = self._writer.register_channel(topic, encoding, schema_id)
            self._channels[topic] = channel
        sequence = self._sequence.get(channel, 0)
        self._sequence[channel] = sequence + 1
        self._writer.add_message(channel, log_time, data, log_time, sequence)
        self.counts.written[topic] = self.counts.written.get(topic, 0) + 1


@dataclass(frozen=True, slots=True)
class Recorded:
    """One message read back: its topic, kind (None: the URDF's channel), log time, and the message as
    the daemon published it (the URDF's: ``{"urdf": text}``)."""

    topic: str
    kind: Kind | None
    log_time_ns: int
    message: dict[str, Any]


def key_of(topic: str, message: dict[str, Any]) -> str:
    """The Zenoh key a recorded message was published on (a goal's topic names no goal: its message
    does)."""
    key = topic[1:]
    parts = key.split("/")
    goal_id = message.get("goal_id")
    if isinstance(goal_id, str) and goal_id:
        if len(parts) == 3 and parts[1] == "goal":
            return f"{parts[0]}/goal/{goal_id}/{parts[2]}"
        if len(parts) == 4 and parts[2] == "goal":
            return f"{parts[0]}/{parts[1]}/goal/{goal_id}/{parts[3]}"
    return key


def _kind_of_topic(topic: str) -> Kind | None:
    parts = topic[1:].split("/")
    if len(parts) == 3 and parts[1] == "goal":
        return KINDS["cell_goal_result"]
    if len(parts) == 4 and parts[2] == "goal":
        return KINDS[f"goal_{parts[3]}"]
    sorted_ = kind_of(topic[1:])
    return None if sorted_ is None else sorted_.kind


def read_recording(stream: IO[bytes], topics: set[str] | None = None) -> Iterator[Recorded]:
    """Every message of a complete recording in log-time order (``topics``: only those)."""
    reader = make_reader(stream)
    for _schema, channel, message in reader.iter_messages(topics=None if topics is None else list(topics)):
        if channel.topic.endswith("/robot_description"):
            yield Recorded(channel.topic, None, message.log_time, {"urdf": cdr.decode_string(message.data)})
            continue
        kind = _kind_of_topic(channel.topic)
        if kind is None:
            continue
        yield Recorded(channel.topic, kind, message.log_time, kind.to_message(message.data, channel.topic))
