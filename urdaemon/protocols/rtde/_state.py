"""The RTDE conversation as a table: where it stands (``RtdeState``), what moves it (``Step``), and
``TRANSITIONS``, (state, step) -> next state, which both parties walk (see ``RtdeConnection``)."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from urdaemon.protocols.rtde._wire import PackageType

__all__ = ["REQUEST_STEPS", "TRANSITIONS", "Request", "RtdeState", "Step"]


class RtdeState(enum.Enum):
    """Where the conversation stands; the same for both parties."""

    IDLE = "idle"  # no output recipe
    CONFIGURED = "configured"  # an output recipe, never started since it was set up
    STARTING = "starting"  # START sent, reply pending (daemon side only)
    RUNNING = "running"  # outputs streaming; inputs may be written
    PAUSING = "pausing"  # PAUSE sent, reply pending (daemon side only)
    PAUSED = "paused"
    ERROR = "error"  # the peer broke the protocol: every later call raises


class Step(enum.Enum):
    """What moves the state: a request, the outcome of its reply, or a data package."""

    REQUEST_VERSION = enum.auto()
    VERSION_ACCEPTED = enum.auto()
    VERSION_REFUSED = enum.auto()
    REQUEST_OUTPUTS = enum.auto()
    OUTPUTS_CONFIGURED = enum.auto()
    OUTPUTS_NOT_FOUND = enum.auto()
    REQUEST_INPUTS = enum.auto()
    INPUTS_ANSWERED = enum.auto()
    REQUEST_START = enum.auto()
    START_ACCEPTED = enum.auto()
    START_REFUSED = enum.auto()
    REQUEST_PAUSE = enum.auto()
    PAUSE_ACCEPTED = enum.auto()
    PAUSE_REFUSED = enum.auto()
    OUTPUT_DATA = enum.auto()
    INPUT_DATA = enum.auto()


_S = RtdeState
TRANSITIONS: Final[Mapping[tuple[RtdeState, Step], RtdeState]] = MappingProxyType(
    {
        # the framing is fixed before anything is set up
        (_S.IDLE, Step.REQUEST_VERSION): _S.IDLE,
        (_S.IDLE, Step.VERSION_ACCEPTED): _S.IDLE,
        (_S.IDLE, Step.VERSION_REFUSED): _S.IDLE,
        # recipes are set up while nothing streams; a failed output setup leaves no output recipe
        # (whether a controller keeps the previous one is unverified; assuming not is the safe side)
        (_S.IDLE, Step.REQUEST_OUTPUTS): _S.IDLE,
        (_S.CONFIGURED, Step.REQUEST_OUTPUTS): _S.CONFIGURED,
        (_S.PAUSED, Step.REQUEST_OUTPUTS): _S.PAUSED,
        (_S.IDLE, Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.CONFIGURED, Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.PAUSED, Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.IDLE, Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.CONFIGURED, Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.PAUSED, Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.IDLE, Step.REQUEST_INPUTS): _S.IDLE,
        (_S.CONFIGURED, Step.REQUEST_INPUTS): _S.CONFIGURED,
        (_S.PAUSED, Step.REQUEST_INPUTS): _S.PAUSED,
        (_S.IDLE, Step.INPUTS_ANSWERED): _S.IDLE,
        (_S.CONFIGURED, Step.INPUTS_ANSWERED): _S.CONFIGURED,
        (_S.PAUSED, Step.INPUTS_ANSWERED): _S.PAUSED,
        # start / pause
        (_S.CONFIGURED, Step.REQUEST_START): _S.STARTING,
        (_S.PAUSED, Step.REQUEST_START): _S.STARTING,
        (_S.STARTING, Step.START_ACCEPTED): _S.RUNNING,
        (_S.STARTING, Step.START_REFUSED): _S.CONFIGURED,
        (_S.RUNNING, Step.REQUEST_PAUSE): _S.PAUSING,
        (_S.PAUSING, Step.PAUSE_ACCEPTED): _S.PAUSED,
        (_S.PAUSING, Step.PAUSE_REFUSED): _S.RUNNING,
        # data: outputs flow while started; urcl takes one arriving before the START reply (§1.6 step 8)
        (_S.STARTING, Step.OUTPUT_DATA): _S.STARTING,
        (_S.RUNNING, Step.OUTPUT_DATA): _S.RUNNING,
        (_S.PAUSING, Step.OUTPUT_DATA): _S.PAUSING,
        # a package the controller queued before it handled PAUSE may trail the reply (unverified):
        # it is still decodable with the recipe, so it is reported rather than called an error
        (_S.PAUSED, Step.OUTPUT_DATA): _S.PAUSED,
        (_S.RUNNING, Step.INPUT_DATA): _S.RUNNING,
    }
)
"""(state, step) -> next state. A pair missing here is out of order (see RtdeConnection)."""

REQUEST_STEPS: Final[Mapping[PackageType, Step | None]] = MappingProxyType(
    {
        PackageType.REQUEST_PROTOCOL_VERSION: Step.REQUEST_VERSION,
        PackageType.GET_URCONTROL_VERSION: None,  # legal in every state, changes nothing
        PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS: Step.REQUEST_OUTPUTS,
        PackageType.CONTROL_PACKAGE_SETUP_INPUTS: Step.REQUEST_INPUTS,
        PackageType.CONTROL_PACKAGE_START: Step.REQUEST_START,
        PackageType.CONTROL_PACKAGE_PAUSE: Step.REQUEST_PAUSE,
    }
)


@dataclass(slots=True)
class Request:
    """A request sent (daemon side) or received (robot side) whose reply is still due."""

    kind: PackageType
    names: tuple[str, ...] = ()
    version: int = 0
