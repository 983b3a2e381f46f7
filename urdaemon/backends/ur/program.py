"""The control program the UR backend runs on the robot: its text, when it is sent, and what is known of it.

The text is rendered once per (host address, controller version) and cached. The host address is
where the callback servers listen (``route.listen_plan``, placed here before RTDE connects), or the
daemon's end of its RTDE link when they listen on every interface. Headless, the backend
sends it on the primary interface, again at most every ``PROGRAM_RESEND_S`` while it has not connected
back; with the External Control URCap the robot fetches it from the script sender. Time is a
parameter (``now``, monotonic seconds): the caller reads the clock.

What the backend knows of its program (when one was started, when it last held all its links, the
link it lost, what the controller said when it ended, why start-up failed) lives here and becomes
the status's reason through ``readiness.not_ready_reason``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from urdaemon.backends.ur.primary_link import PrimaryLink
from urdaemon.backends.ur.readiness import ProgramFacts, not_ready_reason
from urdaemon.backends.ur.reverse_channel import READING_FRAMES, ReverseChannel
from urdaemon.backends.ur.route import ListenPlan
from urdaemon.backends.ur.servers import REPLACED, CallbackServers
from urdaemon.cell.robot_options import Robot, UrOptions
from urdaemon.model import Lifecycle, RobotMode, RobotState
from urdaemon.protocols import primary as prim
from urdaemon.protocols import script_sender

__all__ = ["PROGRAM_RESEND_S", "ControlProgram", "ProgramBuilder"]

log = logging.getLogger("urdaemon.ur")

PROGRAM_RESEND_S = 2.0
"""Headless: after sending the program, wait this long for it to connect back before sending again."""

ProgramBuilder = Callable[[str, UrOptions, dict[str, int]], str]
"""(host address, the robot's ur options, its callback ports) → the program's text."""


class ControlProgram:
    """The control program of one robot (see the module's docstring)."""

    def __init__(
        self,
        robot: Robot,
        options: UrOptions,
        ports: dict[str, int],
        servers: CallbackServers,
        builder: ProgramBuilder | None = None,
    ) -> None:
        self.robot = robot
        self.options = options
        self.ports = ports
        self.servers = servers
        self.builder = builder
        """Renders the text instead of ``urscript.render_control_script`` (tests)."""
        self.host_ip = ""
        """The address the program connects back to: where the servers listen (``plan``), else the
        daemon's side of the RTDE link."""
        self.plan: ListenPlan | None = None
        """Where the callback servers listen and why (``route``; None before they do)."""
        self.controller_version = (5, 10, 0)
        self.sent_at = -1e9
        """When the program was last sent headless."""
        self.started_at = -1e9
        """When a program was last started (its links may replace the old program's)."""
        self.links_up_at = -1e9
        """When the program last held all its links (a program sent after this is still connecting)."""
        self.lost_link = ""
        """The program link that dropped while the others stayed up (the program is being restarted)."""
        self.ended = ""
        """What the controller said when our program last ended (a runtime error, a stop)."""
        self.startup_problem = ""
        """Why the last start-up failed (kept in the status until one succeeds)."""
        self._cache: tuple[tuple[Any, ...], str] | None = None
        self._reason_key: tuple[Any, ...] = ()
        self._reason = ""

    # ---- where it connects back to ----------------------------------------------------------------

    async def listen(self, robot: str) -> None:
        """Have the callback servers listen where the robot at ``robot`` reaches them
        (``CallbackServers.place``), and the program connect back there."""
        plan = self.plan = await self.servers.place(robot, self.options, self.robot.name)
        self.host_ip = plan.connect_back or self.host_ip

    async def rtde_connected(self, peer: str, sockname: str) -> None:
        """RTDE reached the robot at ``peer`` (its IP) from our ``sockname``: if the servers listen for
        another of its IPs (a name that resolves to several), they move; the program connects back to
        where they listen, or to ``sockname`` when they listen on every interface."""
        if self.plan is not None and peer and peer.split("%")[0] != self.plan.robot_ip.split("%")[0]:
            await self.listen(peer)
        back = self.plan.connect_back if self.plan is not None else self.options.reverse_ip
        self.host_ip = back or sockname or "127.0.0.1"

    # ---- the text ----------------------------------------------------------------------------------

    def text(self) -> str:
        """The program's text for this host address and controller version (rendered once)."""
        key = (self.host_ip, self.controller_version)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        text = self._build()
        self._cache = (key, text)
        return text

    def _build(self) -> str:
        if self.builder is not None:
            return self.builder(self.host_ip, self.options, self.ports)
        from urdaemon.urscript import ScriptParameters, render_control_script

        return render_control_script(
            ScriptParameters(
                server_ip=self.host_ip,
                reverse_port=self.ports["reverse"],
                trajectory_port=self.ports["trajectory"],
                script_command_port=self.ports["script_command"],
                servoj_lookahead=self.options.servoj_lookahead,
                servoj_gain=self.options.servoj_gain,
                keepalive_cycles=self.options.keepalive_cycles,
                controller_version=self.controller_version,
            )
        )

    # ---- starting it -------------------------------------------------------------------------------

    def expect(self, now: float) -> None:
        """A new program is starting: its links may replace the old program's, whose closing links
        are not a loss."""
        self.started_at = now
        self.servers.expect_program()

    def due(self, now: float, *, force: bool) -> bool:
        """Whether to send the program headless now (at most every ``PROGRAM_RESEND_S`` unless forced);
        if so, it counts as sent and started now."""
        if not force and now - self.sent_at < PROGRAM_RESEND_S:
            return False
        self.sent_at = now
        self.expect(now)
        return True

    def send_headless(self, primary: PrimaryLink | None, now: float, *, force: bool) -> None:
        """Send the program on the primary interface if it is ``due``."""
        if primary is None or not self.due(now, force=force):
            return
        primary.send_script(prim.headless_program(self.text()))
        log.info("[%s] control program sent (headless, connecting back to %s)", self.robot.name, self.host_ip)

    def send_requested(self, now: float) -> None:
        """The External Control URCap asks for the program: send it on the script sender link."""
        servers = self.servers
        if not self.host_ip:
            # asked before RTDE told us our address: the one the robot just reached us at is right
            link = servers.script_sender.link
            sockname = link.transport.get_extra_info("sockname") if link and link.transport else None
            self.host_ip = self.options.reverse_ip or (str(sockname[0]) if sockname else "")
        if not self.robot.headless and servers.reverse.link is None:
            # the URCap runs it next; a request while a program holds the reverse link (or on a
            # headless robot, whose program the daemon sends itself) opens no way to replace links
            self.expect(now)
        servers.script_sender.send(script_sender.Program(self.text()))
        log.info("[%s] control program sent to the External Control URCap", self.robot.name)

    def still_connecting(self, now: float) -> str | None:
        """Why a resend is refused: the program sent last has not connected back yet (None if not)."""
        pending = now - self.sent_at
        if self.sent_at > self.links_up_at and pending < PROGRAM_RESEND_S:
            return (
                f"the control program sent {pending:.2f} s ago is still connecting back: not sending another"
            )
        return None

    def wanted(self, state: RobotState, runtime_state: int, channel: ReverseChannel) -> bool:
        """Headless, whether the cycle should send the program while it does not hold all its links:
        the robot runs but no program does, or the running one lost a link (a new program brings every
        link back)."""
        servers = self.servers
        return (
            self.robot.headless
            and not self.options.read_only
            and not channel.handed_back
            and state.robot_mode is RobotMode.RUNNING
            and state.lifecycle is Lifecycle.RUNNING
            and (
                # no program: send one
                (
                    not (servers.reverse.connected and runtime_state in READING_FRAMES)
                    and not servers.trajectory.connected
                    and not servers.script_command.connected
                )
                # the program runs but lost a link: a new program brings every link back
                or (servers.reverse.connected and bool(self.lost_link))
            )
        )

    # ---- its links ---------------------------------------------------------------------------------

    def link_up(self, now: float) -> None:
        """A program link came up: if the program started last holds every link (not a mix of the old
        one's and the new one's), it is connected and no connection may replace its links any more."""
        started = self.started_at
        if all(s.link is not None and s.connected_at >= started for s in self.servers.program_links):
            self.links_up_at = now
            self.lost_link = ""
            self.ended = ""
            self.servers.program_connected()

    def replaced_or_closing(self, name: str, reason: str, linked: bool) -> bool:
        """Whether a lost link is no loss of the program: a new program's link takes its place (the old
        program's links close while the new one connects), or the daemon closes them (``linked``
        False: no RTDE link)."""
        return (
            name == "script_sender"
            or reason.endswith(REPLACED)
            or not linked
            or any(s.connected_at < self.started_at for s in self.servers.program_links)
        )

    def link_lost(self, name: str, handed_back: bool) -> None:
        """A program link dropped that no new program replaces: a lost reverse link ended the program
        (it closes the others itself and is sent again); without another, the program runs on without
        it: not ready from now, and repaired (headless)."""
        if name == "reverse":
            return
        others = [s.name for s in self.servers.program_links if s.name != name and s.link is not None]
        if others and not self.lost_link and not handed_back:
            self.lost_link = name
            log.warning(
                "[%s] the control program lost its %s link (%s still connected): %s",
                self.robot.name,
                name,
                ", ".join(others),
                "restarting the program" if self.robot.headless else "not ready until it is restarted",
            )

    # ---- the status's reason -----------------------------------------------------------------------

    def reason(self, state: RobotState, handed_back: bool) -> str:
        """Why the robot cannot take motion now, and what to do about it (only while not ready)."""
        return not_ready_reason(state, self.facts(handed_back))

    def reason_cached(self, state: RobotState, handed_back: bool) -> str:
        """``reason``, worded again only when something it depends on changed (once per cycle)."""
        servers = self.servers
        key = (
            state.lifecycle,
            state.robot_mode,
            state.safety_mode,
            servers.reverse.link,
            servers.trajectory.link,
            servers.script_command.link,
            handed_back,
            self.lost_link,
            self.ended,
            self.startup_problem,
        )
        if key != self._reason_key:
            self._reason_key = key
            self._reason = self.reason(state, handed_back)
        return self._reason

    def facts(self, handed_back: bool) -> ProgramFacts:
        """What the status's reason is worded from."""
        return ProgramFacts(
            read_only=self.options.read_only,
            headless=self.robot.headless,
            handed_back=handed_back,
            lost_link=self.lost_link,
            missing=tuple(self.servers.missing()),
            links=len(self.servers.program_links),
            program_ended=self.ended,
            startup_problem=self.startup_problem,
        )
