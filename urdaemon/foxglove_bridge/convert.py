"""A sample as the daemon published it → the Foxglove messages it becomes: (topic, bytes, log time).
Every kind converts with the recorder's table (``recording/channels.py``) except tf, which goes out
as one transform per URDF joint (``tf_tree.py``). Pure: runs on the bridge's converter thread.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from urdaemon.foxglove_bridge.tf_tree import joint_transforms
from urdaemon.recording import cdr
from urdaemon.recording.channels import kind_of, time_of

__all__ = ["Record", "description_record", "records_of"]

Record = tuple[str, bytes, int]
"""(topic, the message's bytes, its log time in ns)."""


def records_of(key: str, payload: bytes, received_ns: int, joints: Sequence[tuple[str, str]]) -> list[Record]:
    """The messages the sample of ``key`` becomes (none for a key the recorder does not keep). Raises
    ``ValueError`` (or ``KeyError``, ``TypeError``) for a payload that is not the daemon's message."""
    where = kind_of(key)
    if where is None:
        return []
    message = json.loads(payload)
    if not isinstance(message, dict):
        raise ValueError(f"{key}: the message is not a JSON object")
    log_time = time_of(message, received_ns)
    if where.kind.name == "tf":
        return _tf_records(where.topic, message, log_time, joints)
    return [(where.topic, where.kind.to_record(message, key), log_time)]


def _tf_records(
    topic: str, message: dict[str, Any], log_time: int, joints: Sequence[tuple[str, str]]
) -> list[Record]:
    links = message["links"]
    if not isinstance(links, dict):
        raise ValueError(f"{topic}: links is not an object")
    root = str(message.get("frame", "world"))
    return [(topic, cdr.encode_transforms(log_time, joint_transforms(links, joints, root)), log_time)]


def description_record(topic: str, urdf: str, now_ns: int) -> Record:
    """The URDF as the recorder stores it: one ``std_msgs/msg/String``."""
    return (topic, cdr.encode_string(urdf), now_ns)
