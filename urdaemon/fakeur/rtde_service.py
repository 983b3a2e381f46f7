"""A fake controller's RTDE interface (30004): recipes, the output stream, and the inputs it applies.

Each client sets up its output recipe (variables and frequency) and its input recipes; while it
streams, ``send_due`` (called every controller cycle) sends it the outputs whose time has come on the
controller's own time grid, drift-free. Input packages write the arm's IO, the speed slider and the
RTDE input registers (``input_*_register_X`` and the words ``input_bit_registers0_to_31`` /
``32_to_63``), and note when each variable last arrived (what a program's RTDE watchdogs check). An
input variable belongs to the first client that sets it up (IN_USE for the others).

Inputs are taken the way a controller takes them, once per cycle. While the fake keeps time, a
package applies as it arrives (several from one client within one cycle: the last write wins, as on
a controller, so a client sending faster than the controller cycles never falls behind). When the
fake was held up (a cycle came late, or the next one is overdue: the machine was busy), the
packages it then finds were sent over the cycles it missed: at most one package of each client is
applied between two steps of the programs; the ones after it wait in arrival order and
``after_cycle`` (called at the end of every controller cycle) applies the oldest waiting one of each
client. So a fake that was held up and finds two packages of one client (ur_rtde's speedj and its
first watchdog kick) lets its program see each in a cycle of its own, as the cycles a controller
would have run in that time would have. Only this I/O side reads the clock (to tell a stall).

The same holds, whatever the clock says, for several packages of a client found in one read after
an output package went to that client since its previous read: the fake ran that cycle with the
first package unread in its socket, and the output may be what released the others. ur_rtde sends its
watchdog kick right after speedj, but its socket runs with Nagle's algorithm (ur_rtde sets
TCP_NODELAY, then ``boost::asio::connect`` opens a new socket), so the kick leaves only when the
controller's next output package acknowledges speedj. In the fake's model a controller takes its
inputs when its programs step and sends its outputs right after (how a real one phases the two is not
documented), so the kick is read a cycle after speedj. A read's end is told by a callback the loop
runs after the read's packages (``_read_done``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from urdaemon.errors import ProtocolError
from urdaemon.fakeur.connections import Connections, ServiceShell
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.reports import output_getter
from urdaemon.fakeur.urscript.script_host import InputRegisters
from urdaemon.model import CONFIGURABLE_IO_SHIFT, STANDARD_IO_SHIFT, TOOL_IO_SHIFT
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import IN_USE, INPUT_VARIABLES, NOT_FOUND, OUTPUT_VARIABLES

__all__ = ["LATE_CYCLE_PERIODS", "MAX_PENDING_INPUTS", "RtdeService"]

log = logging.getLogger("urdaemon.fakeur")


_DIGITAL_OUTPUT_SHIFTS: Final = (
    ("standard", STANDARD_IO_SHIFT),
    ("configurable", CONFIGURABLE_IO_SHIFT),
    ("tool", TOOL_IO_SHIFT),
)
"""RTDE's digital output inputs (``<kind>_digital_output`` and its mask) and where each kind's pins sit
in the arm's output word."""
LATE_CYCLE_PERIODS = 1.5
"""A cycle that ends more than this many periods after the one before came late: the fake was held up,
and input packages found around it were sent over the cycles it missed (they are then applied one per
cycle). A package that arrives when the next cycle is overdue (more than one period after the latest
ended) is late in the same way. Held up by less, the fake takes a package as a controller would in
that cycle's window: the last write wins."""
MAX_PENDING_INPUTS = 8
"""Input packages of one client waiting for their cycle (a model parameter: 16 ms at 500 Hz). When a
client is further ahead than this (the fake was held up longer, or the client sends faster than the
controller cycles), its oldest waiting package is applied at once to make room: no package is lost
and the lag stays bounded, at the cost of the program missing that package's own cycle."""


@dataclass
class _RtdeClient:
    shell: ServiceShell
    conn: rtde.RtdeConnection
    period: float = 0.0
    next_due: float = 0.0
    streaming: bool = False
    getters: list[Callable[[FakeArm], Any]] = field(default_factory=list)
    inputs: dict[int, tuple[str, ...]] = field(default_factory=dict)
    pending: deque[dict[str, Any]] = field(default_factory=deque)
    """Input packages received and not yet applied, oldest first (one is applied per cycle)."""
    applied_in: int = -1
    """The cycle in which its latest input package was applied (``RtdeService.cycle``)."""
    sent: int = 0
    """Output packages sent to it so far."""
    sent_at_read: int = 0
    """``sent`` when its latest read began."""
    reading: bool = False
    """A read of its packages is being handled: set by the read's first package, cleared once the
    loop has handed over all of that read's packages (a callback run after them)."""
    odd_inputs: int = 0
    """Input packages received of another size than their recipe (each applied as far as it goes)."""
    odd_sizes: set[tuple[int, int]] = field(default_factory=set)
    """The (recipe id, size) pairs of those already logged: each is logged once."""
    after_output: bool = False
    """The read being handled began after an output went to it: packages that sat in the socket
    while the fake sent that output, and those the output released (see ``_receive_inputs``)."""


def _read_done(client: _RtdeClient) -> None:
    """Every package of the client's latest read was handed over (run by the loop after them)."""
    client.reading = False


class RtdeService:
    """The RTDE clients of one controller."""

    def __init__(
        self,
        arm: FakeArm,
        *,
        address: str,
        rate_hz: float,
        controller_version: tuple[int, int, int, int],
        versions: tuple[int, ...],
        input_registers: InputRegisters,
        input_times: dict[str, float],
        wall_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.arm = arm
        self.address = address
        self.rate_hz = rate_hz
        self.controller_version = controller_version
        self.versions = versions
        self.input_registers = input_registers
        self.input_times = input_times
        self.clients: list[_RtdeClient] = []
        """The clients that stream (or streamed and are still connected)."""
        self.waiting: list[_RtdeClient] = []
        """The clients with input packages waiting for a cycle."""
        self.cycle = 0
        """Controller cycles ended (``after_cycle``): inputs applied in one are seen by the next step."""
        self._period = 1.0 / rate_hz
        self._wall_clock = wall_clock
        self._cycle_ended_at = wall_clock()
        """When the latest cycle ended, on the wall clock (how a stall is told)."""
        self._held_up = False
        """The latest cycle came more than ``LATE_CYCLE_PERIODS`` periods after the one before."""
        self.input_owner: dict[str, _RtdeClient] = {}

    def shell(self, connections: Connections, on_read: Callable[[], None]) -> ServiceShell:
        """The shell of one new client connection (``on_read`` after each request handled)."""
        clients: dict[ServiceShell, _RtdeClient] = {}

        def opened(shell: ServiceShell) -> None:
            clients[shell] = _RtdeClient(shell, shell.codec)
            on_read()

        def on_event(shell: ServiceShell, event: Any) -> None:
            self._on_event(clients[shell], event)
            on_read()

        def ended(shell: ServiceShell) -> None:
            self._forget(clients.pop(shell))

        return connections.shell(
            "rtde", rtde.RtdeConnection(Side.ROBOT), on_event, on_open=opened, on_end=ended, paced=True
        )

    def _forget(self, client: _RtdeClient) -> None:
        client.streaming = False
        client.pending.clear()
        with contextlib.suppress(ValueError):
            self.clients.remove(client)
        with contextlib.suppress(ValueError):
            self.waiting.remove(client)
        for name in [n for n, owner in self.input_owner.items() if owner is client]:
            del self.input_owner[name]

    def send_due(self, now: float) -> None:
        """Send every streaming client whose next output package is due at controller time ``now``."""
        arm = self.arm
        for client in self.clients:
            if client.streaming and now + 1e-9 >= client.next_due:
                client.next_due += client.period
                if client.next_due < now:  # fell behind (a stall): resume on the grid, no burst
                    client.next_due = now + client.period
                client.sent += 1
                self._send(client, rtde.OutputData(tuple(get(arm) for get in client.getters)))

    def after_cycle(self) -> None:
        """A controller cycle ended (its programs stepped): the oldest waiting input package of each
        client is applied, for the next step to see."""
        self.cycle += 1
        ended = self._wall_clock()
        self._held_up = ended - self._cycle_ended_at > LATE_CYCLE_PERIODS * self._period
        self._cycle_ended_at = ended
        if self.waiting:
            for client in self.waiting:
                client.applied_in = self.cycle
                self.apply_inputs(client.pending.popleft())
            self.waiting = [client for client in self.waiting if client.pending]

    def _receive_inputs(self, client: _RtdeClient, values: dict[str, Any]) -> None:
        """Apply one input package now if none of this client's was applied since the last step, or
        if one was and the fake keeps time and this package did not come in one read, after an
        output, with the one applied; else queue it for a later cycle (the oldest waiting one
        applied at once when the queue is full)."""
        if not client.reading:
            client.reading = True
            client.after_output = client.sent != client.sent_at_read
            client.sent_at_read = client.sent
            asyncio.get_running_loop().call_soon(_read_done, client)
        if not client.pending and (
            client.applied_in != self.cycle or not (client.after_output or self._behind())
        ):
            client.applied_in = self.cycle
            self.apply_inputs(values)
            return
        if len(client.pending) >= MAX_PENDING_INPUTS:
            self.apply_inputs(client.pending.popleft())
        if not client.pending:
            self.waiting.append(client)
        client.pending.append(values)

    def _behind(self) -> bool:
        """True when the fake was held up: its latest cycle came late, or none came for too long."""
        return self._held_up or self._wall_clock() - self._cycle_ended_at > self._period

    def _send(self, client: _RtdeClient, message: Any) -> None:
        try:
            client.conn.send(message)
        except ProtocolError as err:
            log.info("%s rtde: not sent: %s", self.address, err)
            return
        client.shell.flush()

    def _on_event(self, client: _RtdeClient, event: Any) -> None:
        conn = client.conn
        if isinstance(event, rtde.ProtocolVersionRequested):
            conn.send(rtde.ProtocolVersionAccept(event.version in self.versions))
        elif isinstance(event, rtde.ControllerVersionRequested):
            conn.send(rtde.ControllerVersionReply(*self.controller_version))
        elif isinstance(event, rtde.SetupOutputsRequested):
            self._setup_outputs(client, event)
        elif isinstance(event, rtde.SetupInputsRequested):
            self._setup_inputs(client, event)
        elif isinstance(event, rtde.StartRequested):
            ok = bool(client.getters)
            conn.send(rtde.StartAccept(ok))
            if ok and not client.streaming:
                client.streaming = True
                client.next_due = self.arm.timestamp + client.period
                if client not in self.clients:
                    self.clients.append(client)
        elif isinstance(event, rtde.PauseRequested):
            client.streaming = False
            conn.send(rtde.PauseAccept(True))
        elif isinstance(event, rtde.InputDataReceived):
            input_names = client.inputs.get(event.recipe_id)
            if input_names is None:
                return
            if event.size is not None:
                self._note_odd_size(client, event, event.size, input_names)
            if event.values:
                self._receive_inputs(client, dict(zip(input_names, event.values, strict=False)))
        elif isinstance(event, rtde.TextReceived):
            log.info("%s rtde text from client: %s", self.address, event.message)

    def _note_odd_size(
        self, client: _RtdeClient, event: rtde.InputDataReceived, size: int, names: tuple[str, ...]
    ) -> None:
        """Log the first input package of each size other than its recipe's, per client and recipe;
        count them all (``odd_inputs``)."""
        client.odd_inputs += 1
        key = (event.recipe_id, size)
        if key in client.odd_sizes:
            return
        client.odd_sizes.add(key)
        applied = len(event.values)
        kept = names[applied:]
        log.warning(
            "%s rtde: input package for recipe %d has %s value bytes, the recipe %d: applied its first %d "
            "of %d fields%s; the connection stays (more packages of this size are counted, not logged)",
            self.address,
            event.recipe_id,
            size,
            client.conn.input_recipes[event.recipe_id].size,
            applied,
            len(names),
            f" (not written: {', '.join(kept)})" if kept else ", ignored the bytes after them",
        )

    def _setup_outputs(self, client: _RtdeClient, event: rtde.SetupOutputsRequested) -> None:
        frequency = event.frequency if event.frequency is not None else self.rate_hz
        names = event.names  # an empty name (from ``a,,b``) is answered NOT_FOUND like any unknown
        types = tuple(OUTPUT_VARIABLES.get(name, NOT_FOUND) for name in names)
        # A real controller refuses a frequency it cannot serve: no recipe (id 0), all NOT_FOUND.
        if not (0 < frequency <= self.rate_hz) or NOT_FOUND in types:
            client.getters = []
            client.conn.send(rtde.OutputsSetup(0 if event.frequency is not None else None, types))
            return
        client.period = 1.0 / frequency
        client.getters = [output_getter(name, OUTPUT_VARIABLES[name], self.input_registers) for name in names]
        client.conn.send(rtde.OutputsSetup(1 if event.frequency is not None else None, types))

    def _setup_inputs(self, client: _RtdeClient, event: rtde.SetupInputsRequested) -> None:
        names = event.names
        types = []
        for name in names:
            owner = self.input_owner.get(name)
            if name not in INPUT_VARIABLES:
                types.append(NOT_FOUND)
            elif owner is not None and owner is not client:
                types.append(IN_USE)
            else:
                types.append(INPUT_VARIABLES[name])
        ok = all(t not in (NOT_FOUND, IN_USE) for t in types)
        recipe_id = len(client.inputs) + 1 if ok else 0
        if ok:
            client.inputs[recipe_id] = names
            for name in names:
                self.input_owner[name] = client
        client.conn.send(rtde.InputsSetup(recipe_id, tuple(types)))

    def apply_inputs(self, values: dict[str, Any]) -> None:
        """What an input package does: IO, the speed slider, the input registers."""
        arm, io = self.arm, self.arm.io
        now = arm.timestamp
        for name in values:
            self.input_times[name] = now
        if values.get("speed_slider_mask"):
            fraction = float(values.get("speed_slider_fraction", arm.speed_slider))
            arm.speed_slider = min(max(fraction, 0.0), 1.0)
        for kind, shift in _DIGITAL_OUTPUT_SHIFTS:
            mask = int(values.get(f"{kind}_digital_output_mask", 0)) & 0xFF
            if mask:
                value = int(values.get(f"{kind}_digital_output", 0)) & mask
                io.digital_out = (io.digital_out & ~(mask << shift)) | (value << shift)
        analog_mask = int(values.get("standard_analog_output_mask", 0))
        for pin in (0, 1):
            if analog_mask & (1 << pin):
                io.analog_out[pin] = float(values.get(f"standard_analog_output_{pin}", 0.0))
                if (int(values.get("standard_analog_output_type", 0)) >> pin) & 1:
                    io.analog_out_types |= 1 << (pin + 2)
                else:
                    io.analog_out_types &= ~(1 << (pin + 2))
        self._apply_registers(values)

    def _apply_registers(self, values: dict[str, Any]) -> None:
        registers = self.input_registers
        for name, value in values.items():
            if name.startswith("input_int_register_"):
                registers.ints[int(name.rsplit("_", 1)[1])] = int(value)
            elif name.startswith("input_double_register_"):
                registers.doubles[int(name.rsplit("_", 1)[1])] = float(value)
            elif name.startswith("input_bit_register_"):
                registers.bits[int(name.rsplit("_", 1)[1])] = bool(value)
            elif name.startswith("input_bit_registers"):  # a word: bits 0..31 or 32..63
                low = 0 if name.endswith("0_to_31") else 32
                word = int(value)
                for bit in range(32):
                    registers.bits[low + bit] = bool((word >> bit) & 1)
