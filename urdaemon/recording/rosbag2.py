"""A rosbag2 bag of a ROS 2 recording: the ``metadata.yaml`` that ROS 2's bag tools read beside the
MCAP file, made from the file's own summary.

A rosbag2 bag is a directory holding the storage files and ``metadata.yaml`` (storage ``mcap``,
the files' relative paths, the start, the duration and each topic's type, serialization format and
message count). Only a file whose every channel is a ROS 2 one (``RecordingWriter(ros2_only=True)``,
profile ``ros2``) makes a bag every ROS 2 reader takes: docs/recording.md says why.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader

__all__ = ["METADATA", "bag_metadata", "write_bag_metadata"]

METADATA = "metadata.yaml"
BAG_VERSION = 5
"""rosbag2's metadata version of Humble (read by every later release)."""


def bag_metadata(mcap_path: Path) -> dict[str, Any]:
    """The ``metadata.yaml`` contents for one complete MCAP file of ROS 2 channels."""
    with mcap_path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    if summary is None or summary.statistics is None:
        raise ValueError(f"{mcap_path}: no summary (the file was not closed; recover it first)")
    stats = summary.statistics
    topics = []
    for channel_id, channel in sorted(summary.channels.items()):
        schema = summary.schemas.get(channel.schema_id)
        if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
            raise ValueError(f"{mcap_path}: channel {channel.topic} is not a ROS 2 (CDR) channel")
        topics.append(
            {
                "topic_metadata": {
                    "name": channel.topic,
                    "type": schema.name,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": "",
                },
                "message_count": stats.channel_message_counts.get(channel_id, 0),
            }
        )
    start = stats.message_start_time if stats.message_count else 0
    return {
        "rosbag2_bagfile_information": {
            "version": BAG_VERSION,
            "storage_identifier": "mcap",
            "relative_file_paths": [mcap_path.name],
            "duration": {"nanoseconds": stats.message_end_time - start if stats.message_count else 0},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": stats.message_count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
        }
    }


def write_bag_metadata(mcap_path: Path) -> Path:
    """Write ``metadata.yaml`` beside ``mcap_path`` (its directory becomes the bag); its path."""
    target = mcap_path.parent / METADATA
    target.write_text(yaml.safe_dump(bag_metadata(mcap_path), sort_keys=False))
    return target
