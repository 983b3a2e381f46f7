"""UR's network protocols as sans-IO codecs: bytes in, events out; no asyncio, no sockets, no clock.

Every protocol follows one shape (h11/aioquic style). A small one is a module (``reverse.py`` is the
model); the three large ones, ``rtde/``, ``primary/`` and ``dashboard/``, are packages cut by job as h11
is: ``_wire`` (port, limits, type bytes), the message and event types, their encoding, each side's
logic and ``_connection``; each package's ``__init__`` states its public API. All of them have:

* a ``<Name>Connection(side, ...)`` object per TCP connection, for either party (``Side.DAEMON``
  or ``Side.ROBOT``: the fake controller uses the robot side of the same codecs);
* ``receive_data(data) -> list[Event]``: feed any chunk of received bytes (a whole message, a part
  of one, or several); returns the events completed so far. Bad bytes raise
  ``RemoteProtocolError`` (never anything else) and move the connection to an error state in
  which every later call raises too;
* ``send(message) -> None`` queues a message; ``data_to_send() -> bytes`` returns and clears what
  is queued, so the pump has a single write path. Sending what the protocol forbids raises
  ``LocalProtocolError``;
* events and messages are frozen, slotted dataclasses named for what happened;
* the stream codecs share one base, ``_codec.Codec``: side, the error state (``_stream``), the
  receive buffer with its limit, the feed loop calling the codec's ``_parse`` step, the one outgoing
  buffer behind ``send``/``data_to_send``, and the two error helpers. A codec brings only its parse
  step, its ``_encode`` and its own conversation state (RTDE's table, for example); the fixed-frame
  callback codecs share ``_fixed.FixedFrameConnection``;
* wire layouts are drawn in each codec's docstring; every limit is a named constant with its unit.

The reference for every format is ``docs/protocols.md``; a ``§N.M`` in these modules names its section.
"""

from __future__ import annotations

from urdaemon.protocols._buffer import ReceiveBuffer, Side

__all__ = ["ReceiveBuffer", "Side"]
