"""Keyboard teleop in a terminal (``urdaemon teleop ROBOT``): the terminal's shell around
teleop_keys.py's pure state machine.

It puts the terminal in raw mode (restored on every way out: quit keys, a signal, an error), reads
the keys as they come (the loop's reader on stdin), and every ``PERIOD_S`` sends the state machine's
twist while a motion key is held; when the keys stop, it sends ``ZERO_SENDS`` zero twists (the robot
decelerates) and then nothing (the daemon's deadman, the robot's stream timeout, stops it anyway).
One line, rewritten in place, shows the TCP pose (from the robot's ``tcp_pose``), the speed, the
frame, what moves, and the daemon's last refusal of a twist (a ``command_rejected`` event).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, TextIO

from urdaemon.errors import UrDaemonError
from urdaemon.teleop_keys import ZERO, TeleopKeys, keys_of, status_line

if TYPE_CHECKING:
    from urdaemon.client import RobotClient

__all__ = ["PERIOD_S", "ZERO_SENDS", "TeleopShell", "raw_terminal"]

PERIOD_S = 0.02
"""Twists go out every 20 ms while a key is held: well within any stream timeout (0.2 s by default)."""
LINE_PERIOD_S = 0.1
"""The live line is rewritten at most this often."""
ZERO_SENDS = 5
"""Zero twists sent once the keys stopped (the robot decelerates), before sending nothing at all."""
REFUSAL_SHOWN_S = 3.0
"""How long the line shows the daemon's last refusal of a twist."""
QUIT_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def raw_terminal(fd: int) -> Iterator[None]:
    """The terminal ``fd`` in raw mode (every key as it is typed, Ctrl-C as a character, no echo) for
    the block; its settings put back however the block ends."""
    import termios
    import tty

    saved = termios.tcgetattr(fd)
    try:
        tty.setraw(fd, termios.TCSANOW)
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


class TeleopShell:
    """Keys from ``fd`` to twists of ``robot`` until a quit key or a signal; the live line to ``out``."""

    def __init__(self, robot: RobotClient, keys: TeleopKeys, fd: int, out: TextIO) -> None:
        self.robot = robot
        self.keys = keys
        self.fd = fd
        self.out = out
        self.sent = 0
        """Twists sent (zero ones included)."""
        self._zeros = ZERO_SENDS  # nothing to stop at the start
        self._pose: bytes | None = None
        self._refusal: tuple[str, float] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    async def run(self) -> int:
        """Teleop until quit; 0, or 1 after saying why twists could not be sent (e.g. the lease was
        taken over). The caller holds the terminal raw and the robot's lease."""
        loop = self._loop = asyncio.get_running_loop()
        session = self.robot.client.session
        watched = [
            session.declare_subscriber(self.robot.keys.tcp_pose, self._on_pose),
            session.declare_subscriber(self.robot.keys.events, self._on_event),
        ]
        loop.add_reader(self.fd, self._on_input)
        handled = []
        for sig in QUIT_SIGNALS:  # SIGTERM, SIGHUP (the terminal closed): quit as x does
            with contextlib.suppress(ValueError, RuntimeError):  # only the main thread may
                loop.add_signal_handler(sig, self._quit)
                handled.append(sig)
        try:
            return await self._ticks(loop)
        finally:
            loop.remove_reader(self.fd)
            for sig in handled:
                loop.remove_signal_handler(sig)
            for sub in watched:
                with contextlib.suppress(Exception):
                    sub.undeclare()
            with contextlib.suppress(UrDaemonError):
                self._send(ZERO)  # the robot decelerates now, not only at the deadman
            self.out.write("\r\n")
            self.out.flush()

    async def _ticks(self, loop: asyncio.AbstractEventLoop) -> int:
        next_tick = next_line = loop.time()
        while not self.keys.done:
            now = loop.time()
            twist = self.keys.twist(now)
            try:
                if not twist.zero:
                    self._send(twist)
                    self._zeros = 0
                elif self._zeros < ZERO_SENDS:
                    self._send(ZERO)
                    self._zeros += 1
            except UrDaemonError as err:
                self.out.write(f"\r\nerror: {err}\r\n")
                return 1
            if now >= next_line:
                self._show(now)
                next_line = now + LINE_PERIOD_S
            next_tick = max(next_tick + PERIOD_S, now)  # a fixed rate; no burst after a stall
            await asyncio.sleep(max(0.0, next_tick - loop.time()))
        self._show(loop.time())
        return 0

    def _send(self, twist: Any) -> None:
        self.robot.twist(twist.linear, twist.angular, frame=self.keys.frame)
        self.sent += 1

    def _show(self, now: float) -> None:
        line = status_line(self.robot.name, self._last_pose(), self.keys, now)
        if self._refusal is not None and now - self._refusal[1] < REFUSAL_SHOWN_S:
            line += f" | refused: {self._refusal[0]}"
        self.out.write(f"\r{line[: self._width() - 1]}\x1b[K")  # a wrapped line could not be rewritten
        self.out.flush()

    def _width(self) -> int:
        """The terminal's width now (it may be resized), 80 when ``out`` is no terminal."""
        try:
            return os.get_terminal_size(self.out.fileno()).columns
        except (OSError, ValueError, AttributeError):
            return 80

    def _last_pose(self) -> dict[str, object] | None:
        payload = self._pose
        if payload is None:
            return None
        with contextlib.suppress(ValueError):
            data = json.loads(payload)
            if isinstance(data, dict):
                return data
        return None

    def _on_input(self) -> None:
        try:
            data = os.read(self.fd, 1024)
        except OSError:
            data = b""
        if not data:  # the terminal went away
            self._quit()
            return
        assert self._loop is not None
        now = self._loop.time()
        for key in keys_of(data.decode(errors="replace")):
            self.keys.feed(key, now)

    def _quit(self) -> None:
        self.keys.feed("x", 0.0)

    def _on_pose(self, sample: Any) -> None:
        """On Zenoh's thread: keep the newest tcp_pose (decoded only when the line is drawn)."""
        self._pose = sample.payload.to_bytes()

    def _on_event(self, sample: Any) -> None:
        """On Zenoh's thread: a ``command_rejected`` event about twists is shown on the line."""
        payload = sample.payload.to_bytes()
        if b"command_rejected" not in payload:
            return
        with contextlib.suppress(ValueError, RuntimeError):
            event = json.loads(payload)
            if isinstance(event, dict) and str(event.get("key", "")).endswith("command/twist"):
                loop = self._loop
                if loop is not None:
                    loop.call_soon_threadsafe(self._refused, str(event.get("reason", "")))

    def _refused(self, reason: str) -> None:
        assert self._loop is not None
        self._refusal = (reason[:120], self._loop.time())
