"""The bytes the UR backend writes to its control program: the reverse channel's frames and actions
on the reverse socket, passthrough points on the trajectory socket.

``ReverseChannel`` decides what goes out; ``ReverseWriter`` writes it. The frames that never change
(keepalives, trajectory and freedrive control) are encoded once; servoj is packed without building a
message (the 500 Hz path).

Every frame carries the robot's window (``ur.receive_timeout_ms``) as its read timeout: the program
ends only when no frame at all arrives for that long. Within it, a servoj or speedj stream goes on for
``ur.keepalive_cycles`` and then stops, and a trajectory or freedrive goes on (the control script).
"""

from __future__ import annotations

from urdaemon.backends.ur.reverse_channel import Action, Frame, Step
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.errors import BackendError, LocalProtocolError
from urdaemon.model import JointCommand
from urdaemon.protocols import reverse, trajectory_point

__all__ = ["ReverseWriter", "encode_passthrough_point"]

_SERVOJ, _SPEEDJ, _NONE = Frame.SERVOJ, Frame.SPEEDJ, Frame.NONE
"""(the 500 Hz path: an enum's attribute lookup costs ~0.1 µs, a module alias a fifth of that)"""
_T = reverse.TrajectoryAction
_F = reverse.FreedriveAction


class ReverseWriter:
    """Writes the channel's frames and actions to the reverse (and trajectory) server."""

    def __init__(self, servers: CallbackServers, receive_timeout_ms: int) -> None:
        self.servers = servers
        self.receive_timeout_ms = receive_timeout_ms
        self.window = receive_timeout_ms / 1000.0
        """The read timeout of every frame, s: the configured window, at least one controller step."""
        self._frames: dict[Frame, bytes] = {}
        self._actions: dict[Action, reverse.ReverseCommand] = {}
        self.use_step(0.0)

    def use_step(self, step_time: float) -> None:
        """The controller's step (s): encode every constant frame and action with the window."""
        window = self.window = max(self.receive_timeout_ms / 1000.0, step_time)
        constant: dict[Frame, reverse.ReverseCommand] = {
            Frame.IDLE: reverse.Idle(window),
            Frame.TRAJECTORY_NOOP: reverse.TrajectoryControl(_T.NOOP, 0, window),
            Frame.FREEDRIVE_NOOP: reverse.FreedriveControl(_F.NOOP, window),
            Frame.FREEDRIVE_STOP: reverse.FreedriveControl(_F.STOP, window),
        }
        self._frames = {frame: reverse.encode_reverse_command(m) for frame, m in constant.items()}
        self._actions = {
            Action.SEND_CANCEL: reverse.TrajectoryControl(_T.CANCEL, 0, window),
            Action.SEND_FREEDRIVE_START: reverse.FreedriveControl(_F.START, window),
            Action.SEND_FREEDRIVE_STOP: reverse.FreedriveControl(_F.STOP, window),
            Action.SEND_STOPPED: reverse.Stopped(),
        }

    def write(self, frame: Frame, command: JointCommand) -> None:
        """This cycle's frame (``Frame.NONE``: nothing)."""
        server = self.servers.reverse
        if frame is _SERVOJ:
            server.write(reverse.encode_servoj(command.positions, self.window))
        elif frame is _SPEEDJ:
            server.send(reverse.SpeedJ(tuple(command.velocities), self.window))
        elif frame is not _NONE:
            server.write(self._frames[frame])

    def act(self, step: Step) -> None:
        """Send what an event's step asks for on the reverse socket (START has its own method)."""
        message = self._actions.get(step.action)
        if message is not None:
            self.servers.reverse.send(message)

    def start(self, frames: bytes, count: int) -> None:
        """START(count) on the reverse socket, then the pre-encoded points on the trajectory socket."""
        self.servers.reverse.send(
            reverse.TrajectoryControl(reverse.TrajectoryAction.START, count, self.window)
        )
        self.servers.trajectory.write(frames)


def encode_passthrough_point(
    positions: tuple[float, ...],
    velocities: tuple[float, ...],
    accelerations: tuple[float, ...] | None,
    segment_time: float,
) -> bytes:
    """One spline point's 84-byte frame; BackendError for a value the wire cannot carry (a segment
    longer than trajectory_point.MAX_DURATION_S, a non-finite or too large value)."""
    if segment_time > trajectory_point.MAX_DURATION_S:
        raise BackendError(
            f"a segment of {segment_time:.6g} s is longer than the robot can take"
            f" (at most {trajectory_point.MAX_DURATION_S:g} s between two points)"
        )
    try:
        return trajectory_point.encode_point(
            trajectory_point.SplinePoint(positions, velocities, accelerations, segment_time)
        )
    except LocalProtocolError as err:
        raise BackendError(f"cannot send the trajectory to the robot: {err}") from None
