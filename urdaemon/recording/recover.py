"""Recovering a recording that was cut short (kill -9, power loss, a full disk): every record up to
the last complete chunk, written again as a complete MCAP file.

A recorder writes the file as a stream of records: the header, then chunks (each a compressed run of
schemas, channels and messages, written whole), then, when it finishes, the summary and the footer.
Cut short, the file ends inside a chunk (or between two) and has no summary, so readers that start
from the summary refuse it. ``recover`` reads it from the start with mcap's stream reader, record by
record, stops at the first one that is not whole (or whose CRC does not match), and writes every
schema, channel, message, attachment and metadata record before it into a new file, which ``finish``
completes with its summary and index. ``scan`` counts what a recovery would keep, writing nothing.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import IO, Any

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

__all__ = ["Recovered", "recover", "scan"]


@dataclass(slots=True)
class Recovered:
    """What a recovery kept, and where and why reading stopped."""

    messages: int = 0
    attachments: int = 0
    metadata: int = 0
    last_log_time_ns: int = 0
    """The latest log time among the messages kept (0: none)."""
    complete: bool = False
    """The source was a complete file (it had its footer): nothing was lost."""
    stopped: str = ""
    """Why reading stopped before the end (empty when ``complete``)."""


class _Whole:
    """A byte stream whose ``read(n)`` returns n bytes or raises: a record cut short is never parsed."""

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self.offset = 0

    def read(self, size: int = -1) -> bytes:
        data = self._stream.read(size)
        if size >= 0 and len(data) < size:
            raise EOFError(f"the file ends {self.offset + len(data)} bytes in, inside a record")
        self.offset += len(data)
        return data


class _Copy:
    """Writes the records read into a new file, with new schema and channel ids."""

    def __init__(self, output: IO[bytes]) -> None:
        self._writer = Writer(output, compression=CompressionType.ZSTD)
        self._started = False
        self._schemas: dict[int, int] = {0: 0}
        self._channels: dict[int, int] = {}

    def add(self, record: Any) -> None:
        w = self._writer
        if isinstance(record, Header):
            w.start(profile=record.profile, library=record.library)
            self._started = True
        elif isinstance(record, Schema) and record.id not in self._schemas:
            self._schemas[record.id] = w.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel) and record.id not in self._channels:
            schema = self._schemas.get(record.schema_id, 0)
            self._channels[record.id] = w.register_channel(
                record.topic, record.message_encoding, schema, record.metadata
            )
        elif isinstance(record, Message) and record.channel_id in self._channels:
            channel = self._channels[record.channel_id]
            w.add_message(channel, record.log_time, record.data, record.publish_time, record.sequence)
        elif isinstance(record, Attachment):
            w.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
        elif isinstance(record, Metadata):
            w.add_metadata(record.name, record.metadata)

    def finish(self) -> None:
        if not self._started:
            self._writer.start()
        self._writer.finish()  # type: ignore[no-untyped-call]


def _count(record: Any, result: Recovered) -> None:
    if isinstance(record, Message):
        result.messages += 1
        result.last_log_time_ns = max(result.last_log_time_ns, record.log_time)
    elif isinstance(record, Attachment):
        result.attachments += 1
    elif isinstance(record, Metadata):
        result.metadata += 1


def _read(source: IO[bytes], copy: _Copy | None) -> Recovered:
    result = Recovered()
    whole = _Whole(source)
    reader = StreamReader(whole, validate_crcs=True)  # type: ignore[arg-type]
    try:
        for record in reader.records:
            if isinstance(record, DataEnd | Footer):
                result.complete = True
                break  # the summary repeats what the data section held
            if copy is not None:
                copy.add(record)
            _count(record, result)
    except (EOFError, McapError, struct.error, zlib.error, ValueError, UnicodeDecodeError) as err:
        text = str(err) or type(err).__name__
        result.stopped = f"{text} (read up to byte {whole.offset})"
    except Exception as err:  # a decompressor's own error on a damaged chunk: stop there too
        result.stopped = f"{type(err).__name__}: {err} (read up to byte {whole.offset})"
    return result


def recover(source: IO[bytes], output: IO[bytes]) -> Recovered:
    """Copy every whole record of ``source`` into ``output`` and complete it; what was kept."""
    copy = _Copy(output)
    result = _read(source, copy)
    copy.finish()
    return result


def scan(source: IO[bytes]) -> Recovered:
    """What ``recover`` would keep of ``source``, writing nothing."""
    return _read(source, None)
