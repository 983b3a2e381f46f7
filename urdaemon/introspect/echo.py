"""``urdaemon echo``'s options: ``--field`` (one field of each message), ``--rate`` (at most so many
messages a second, per key) and the warning when nothing publishes on the key (docs/introspection.md).
The field picking and the thinning are pure; ``echo_command`` is the asyncio shell."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence

from urdaemon.errors import UrDaemonError, UrTimeoutError
from urdaemon.introspect.connection import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, connect, error
from urdaemon.introspect.silence import SILENCE_S, explain
from urdaemon.introspect.survey import survey

__all__ = ["FieldMissing", "Thinner", "echo_command", "pick_field"]


class FieldMissing(UrDaemonError):
    """``--field`` names a field the message does not have (the message names the fields it has)."""


def pick_field(value: object, path: str) -> object:
    """The field ``a.b.0`` of a decoded message (list items by index); ``FieldMissing`` naming the
    first chunk that is not there and what there is at that level."""
    current = value
    walked: list[str] = []
    for chunk in path.split("."):
        if isinstance(current, Mapping) and chunk in current:
            current = current[chunk]
        elif isinstance(current, Sequence) and not isinstance(current, str) and chunk.isdigit():
            if int(chunk) >= len(current):
                raise FieldMissing(
                    f"field {path!r}: {'.'.join(walked) or 'the message'} has {len(current)} items"
                )
            current = current[int(chunk)]
        else:
            at = ".".join(walked) or "the message"
            if isinstance(current, Mapping):
                there = f"its fields: {', '.join(str(k) for k in current)}"
            elif isinstance(current, Sequence) and not isinstance(current, str):
                there = f"a list of {len(current)}: index it by number"
            else:
                there = f"a {type(current).__name__}, no fields"
            raise FieldMissing(f"no field {chunk!r} in {at} ({there})")
        walked.append(chunk)
    return current


class Thinner:
    """At most ``rate_hz`` messages a second of each key pass (None: all)."""

    def __init__(self, rate_hz: float | None) -> None:
        self._period = 0.0 if rate_hz is None else 1.0 / rate_hz
        self._last: dict[str, float] = {}

    def passes(self, key: str, now_s: float) -> bool:
        """Whether a message of ``key`` received at ``now_s`` (monotonic s) is shown."""
        last = self._last.get(key)
        if last is not None and now_s - last < self._period:
            return False
        # advance by whole periods: a 500 Hz stream thinned to 10 Hz shows 10 a second, not 9.x
        self._last[key] = now_s if last is None or now_s - last >= 2 * self._period else last + self._period
        return True


def _decoded(payload: bytes) -> object:
    try:
        return json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError):
        return payload.decode(errors="replace")


async def _silence_verdict(client: object, key: str, waited: float) -> bool:
    """Say on stderr why nothing came on ``key``; whether waiting may still help."""
    from urdaemon.client import Client

    assert isinstance(client, Client)
    verdict = explain(key, await survey(client), waited)
    print(f"{'note' if verdict.published else 'warning'}: {verdict.text}", file=sys.stderr, flush=True)
    return verdict.published


async def echo_command(args: argparse.Namespace) -> int:
    """Print the samples of ``args.key`` as JSON lines (``--field``, ``--rate``, ``--count``,
    ``--timeout``); warn after ``SILENCE_S`` s without a sample why none came, and give up then when
    nothing publishes on the key, unless ``--timeout`` was given (it alone decides how long to wait)."""
    key, count, timeout = args.key, args.count, args.timeout
    thinner = Thinner(args.rate)
    try:
        client = await connect(args)
    except UrDaemonError as err:
        return error(_message(err))
    async with client:
        sub = client.subscribe(key)
        received, started, looked = 0, time.monotonic(), False
        while count <= 0 or received < count:
            wait = _wait(timeout, received, looked, time.monotonic() - started)
            try:
                sample_key, payload = await sub.get(wait)
            except UrTimeoutError as err:
                if looked or received or (timeout and time.monotonic() - started >= timeout):
                    return error(f"no sample on {key} within {timeout:g} s" if timeout else _message(err))
                looked = True
                if not await _silence_verdict(client, key, SILENCE_S) and timeout is None:
                    return EXIT_FAILED
                continue
            except UrDaemonError as err:
                return error(_message(err))
            if not thinner.passes(sample_key, time.monotonic()):
                continue
            value = _decoded(payload)
            if args.field is not None:
                try:
                    value = pick_field(value, args.field)
                except FieldMissing as err:
                    return error(f"{sample_key}: {err}", EXIT_BAD_INPUT)
            print(json.dumps({"key": sample_key, "value": value}), flush=True)
            received += 1
    return EXIT_OK


def _wait(timeout: float | None, received: int, looked: bool, waited: float) -> float | None:
    """How long to wait for the next sample: ``--timeout`` (from the start for the first sample),
    cut to ``SILENCE_S`` for the first look into why nothing came."""
    wait = (timeout - waited if received == 0 else timeout) if timeout else None
    if not looked and received == 0:
        wait = SILENCE_S if wait is None else min(wait, SILENCE_S)
    return None if wait is None else max(wait, 0.0)


def _message(err: BaseException) -> str:
    from urdaemon.client import zenoh_message

    return zenoh_message(err)
