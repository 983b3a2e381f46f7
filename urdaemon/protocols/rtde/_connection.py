"""``RtdeConnection``: one RTDE connection, for either party; both sides' jobs behind one codec."""

from __future__ import annotations

from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde._daemon import DaemonSide
from urdaemon.protocols.rtde._robot import RobotSide

__all__ = ["RtdeConnection"]


class RtdeConnection(DaemonSide, RobotSide):
    """One RTDE connection for either party: ``receive_data`` → events, ``send`` → ``data_to_send``.

    State: ``TRANSITIONS`` maps (state, step) to the next state; both parties walk the same table::

        IDLE, CONFIGURED, PAUSED  --setup outputs, all found-->  CONFIGURED
        IDLE, CONFIGURED, PAUSED  --setup outputs, NOT_FOUND-->  IDLE
        CONFIGURED, PAUSED        --START-->                     STARTING
        STARTING                  --accepted / refused-->        RUNNING / CONFIGURED
        RUNNING                   --PAUSE-->                     PAUSING
        PAUSING                   --accepted / refused-->        PAUSED / RUNNING
        (version changes only in IDLE; input setups in IDLE, CONFIGURED, PAUSED change nothing;
         output data in STARTING, RUNNING, PAUSING, PAUSED; input data in RUNNING)

    The daemon side passes through STARTING and PAUSING while its request is out; the robot side
    handles request and answer in one go and never rests there.

    Requests (§1.6): urcl and UR's client send one request and wait for its reply, so the DAEMON side
    allows one outstanding request. Sending a second first, or a request the table does not allow
    now (START before outputs are set up, input data before START, a version change after setup),
    raises LocalProtocolError and changes nothing. A reply nobody asked for is a RemoteProtocolError.

    The ROBOT side reports every well-formed request as an event, in order or not, and keeps the
    unanswered ones oldest first; the fake answers each exactly once, in that order. Order is judged
    when the answer is sent (a controller handles requests one by one). The answer to an
    out-of-order request leaves the state alone. Where the reply has an "accepted" byte, a
    controller answers 0 (START or PAUSE before setup); the codec lets the fake answer as it likes
    except where the answer would make no sense to the codec itself: accepting a version after
    setup or one it cannot speak, accepting START without an output recipe.

    Errors: bad bytes raise RemoteProtocolError (``offset`` = stream offset of the offending package)
    and leave the connection in ERROR, where every later call raises. A refused ``send`` raises
    LocalProtocolError and queues nothing.
    """

    def __init__(self, side: Side, *, protocol_version: int = 2) -> None:
        """``protocol_version`` is the framing in force until the robot accepts a REQUEST_PROTOCOL_VERSION."""
        super().__init__(side, protocol_version=protocol_version)
        if side is Side.DAEMON:
            self._daemon_tables()
        else:
            self._robot_tables()
