"""The robot's side of RTDE (the fake controller's): decode requests and input data, send answers."""

from __future__ import annotations

import struct
from collections.abc import Sequence

from urdaemon.protocols.rtde._core import RtdeCore
from urdaemon.protocols.rtde._events import (
    ControllerVersion,
    ControllerVersionReply,
    ControllerVersionRequested,
    InputDataReceived,
    InputsSetup,
    OutputData,
    OutputsSetup,
    PauseAccept,
    PauseRequested,
    ProtocolVersionAccept,
    ProtocolVersionRequested,
    SetupInputsRequested,
    SetupOutputsRequested,
    StartAccept,
    StartRequested,
    Text,
)
from urdaemon.protocols.rtde._recipe import INPUT_ANSWERS, OUTPUT_ANSWERS, Recipe
from urdaemon.protocols.rtde._state import REQUEST_STEPS, TRANSITIONS, Request, Step
from urdaemon.protocols.rtde._wire import (
    F64,
    MAX_RECIPE_NAMES_BYTES,
    MAX_UNANSWERED_REQUESTS,
    SUPPORTED_PROTOCOL_VERSIONS,
    U8,
    U16,
    VERSION4,
    Buf,
    PackageType,
    local_error,
)
from urdaemon.protocols.rtde_variables import IN_USE, NOT_FOUND

__all__ = ["RobotSide"]


class RobotSide(RtdeCore):
    """The robot's job (the fake's side): decode requests and input data, send answers and outputs."""

    def _robot_tables(self) -> None:
        P = PackageType
        self._handlers = {
            P.REQUEST_PROTOCOL_VERSION: self._on_version_request,
            P.GET_URCONTROL_VERSION: self._on_controller_version_request,
            P.CONTROL_PACKAGE_SETUP_OUTPUTS: self._on_outputs_request,
            P.CONTROL_PACKAGE_SETUP_INPUTS: self._on_inputs_request,
            P.CONTROL_PACKAGE_START: self._on_start_request,
            P.CONTROL_PACKAGE_PAUSE: self._on_pause_request,
            P.DATA_PACKAGE: self._on_input_data,
            P.TEXT_MESSAGE: self._on_text_from_client,
        }
        self._senders = {
            ProtocolVersionAccept: self._send_version_answer,
            ControllerVersionReply: self._send_controller_version,
            OutputsSetup: self._send_outputs_answer,
            InputsSetup: self._send_inputs_answer,
            StartAccept: self._send_start_answer,
            PauseAccept: self._send_pause_answer,
            OutputData: self._send_output_data,
            Text: self._send_text,
        }

    # -- ROBOT: requests and data ----------------------------------------------------------------

    def _received(self, request: Request) -> None:
        if len(self._requests) >= MAX_UNANSWERED_REQUESTS:
            raise self._bad(f"more than {MAX_UNANSWERED_REQUESTS} requests without waiting for replies")
        self._requests.append(request)

    def _names(self, buf: Buf, start: int, end: int, kind: PackageType) -> tuple[str, ...]:
        if end <= start:
            raise self._bad(f"{kind.name} request without variable names")
        if end - start > MAX_RECIPE_NAMES_BYTES:
            raise self._bad(
                f"{kind.name} names take {end - start} bytes, the limit is {MAX_RECIPE_NAMES_BYTES}"
            )
        try:
            names = str(buf[start:end], "ascii").split(",")
        except UnicodeDecodeError:
            raise self._bad(f"{kind.name} names are not ASCII") from None
        # ur_rtde ends its list with a comma and works against real controllers: a trailing comma
        # adds no name there, so it adds none here either
        if len(names) > 1 and names[-1] == "":
            names.pop()
        return tuple(names)

    def _on_version_request(self, buf: Buf, start: int, end: int) -> ProtocolVersionRequested:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        if end - start != U16.size:
            raise self._bad(f"{kind.name} request has {end - start} payload bytes, expected 2")
        version: int = U16.unpack_from(buf, start)[0]
        self._received(Request(kind, version=version))
        return ProtocolVersionRequested(version)

    def _on_controller_version_request(self, buf: Buf, start: int, end: int) -> ControllerVersionRequested:
        kind = PackageType.GET_URCONTROL_VERSION
        self._empty(start, end, kind)
        self._received(Request(kind))
        return ControllerVersionRequested()

    def _on_outputs_request(self, buf: Buf, start: int, end: int) -> SetupOutputsRequested:
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        frequency: float | None = None
        if self._version >= 2:
            if end - start < F64.size:
                raise self._bad(f"{kind.name} request shorter than its frequency")
            frequency = F64.unpack_from(buf, start)[0]
            start += F64.size
        names = self._names(buf, start, end, kind)
        self._received(Request(kind, names=names))
        return SetupOutputsRequested(frequency, names)

    def _on_inputs_request(self, buf: Buf, start: int, end: int) -> SetupInputsRequested:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        names = self._names(buf, start, end, kind)
        self._received(Request(kind, names=names))
        return SetupInputsRequested(names)

    def _on_start_request(self, buf: Buf, start: int, end: int) -> StartRequested:
        kind = PackageType.CONTROL_PACKAGE_START
        self._empty(start, end, kind)
        self._received(Request(kind))
        return StartRequested()

    def _on_pause_request(self, buf: Buf, start: int, end: int) -> PauseRequested:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        self._empty(start, end, kind)
        self._received(Request(kind))
        return PauseRequested()

    def _on_input_data(self, buf: Buf, start: int, end: int) -> InputDataReceived:
        # reported in any state: whether inputs count before START is the fake's call (unverified)
        if end <= start:
            raise self._bad("input DATA_PACKAGE without its recipe id")
        recipe_id = buf[start]
        recipe = self._input_recipes.get(recipe_id)
        if recipe is None:
            raise self._bad(f"input DATA_PACKAGE for input recipe {recipe_id}, which was never set up")
        size = end - start - 1
        if size != recipe.size:  # the recipe's leading fields the package holds whole; the rest unread
            return InputDataReceived(recipe_id, recipe.decode_leading(buf, start + 1, size), size)
        return InputDataReceived(recipe_id, recipe.decode(buf, start + 1))

    # -- ROBOT: answers and data -----------------------------------------------------------------

    def _answering(self, kind: PackageType) -> tuple[Request, bool]:
        """The oldest unanswered request, which must be of ``kind``, and whether it is in order now."""
        if not self._requests:
            raise local_error(f"{kind.name} reply, but no request is waiting for one")
        request = self._requests[0]
        if request.kind is not kind:
            raise local_error(f"{kind.name} reply, but the oldest unanswered request is {request.kind.name}")
        step = REQUEST_STEPS[kind]
        return request, step is None or (self._state, step) in TRANSITIONS

    def _answer(self, kind: PackageType, payload: bytes, outcome: Step | None, in_order: bool) -> None:
        """Queue the reply to the oldest request and walk request + outcome through the table if in order."""
        state = self._state
        step = REQUEST_STEPS[kind]
        if in_order and step is not None and outcome is not None:
            state = TRANSITIONS[(state, step)]
            after = TRANSITIONS.get((state, outcome))
            if after is None:
                raise local_error(f"{outcome.name} cannot follow {step.name} in state {self._state.name}")
            state = after
        self._emit(kind, payload)
        self._state = state
        self._requests.popleft()

    def _send_version_answer(self, message: ProtocolVersionAccept) -> None:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        request, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        if accepted and not in_order:
            raise local_error(
                f"accepting a protocol version in state {self._state.name}; answer accepted=False"
            )
        if accepted and request.version not in SUPPORTED_PROTOCOL_VERSIONS:
            raise local_error(
                f"this codec cannot speak protocol version {request.version}; answer accepted=False"
            )
        outcome = Step.VERSION_ACCEPTED if accepted else Step.VERSION_REFUSED
        self._answer(kind, U8.pack(accepted), outcome, in_order)
        if accepted:
            self._version = request.version

    def _send_controller_version(self, message: ControllerVersionReply) -> None:
        kind = PackageType.GET_URCONTROL_VERSION
        self._answering(kind)
        version = ControllerVersion(message.major, message.minor, message.bugfix, message.build)
        try:
            payload = VERSION4.pack(version.major, version.minor, version.bugfix, version.build)
        except struct.error as err:
            raise local_error(f"controller version fields must be uint32: {err}") from err
        self._answer(kind, payload, None, True)
        self._controller_version = version

    def _setup_answer(
        self, kind: PackageType, recipe_id: int | None, types: Sequence[str], allowed: frozenset[str]
    ) -> tuple[Request, bool, tuple[str, ...], bytes]:
        """Checks shared by both setup answers: (request, in order, types, payload)."""
        request, in_order = self._answering(kind)
        answers = tuple(types)
        if len(answers) != len(request.names):
            raise local_error(f"{kind.name} reply needs one type per requested name ({len(request.names)})")
        for rtde_type in answers:
            if rtde_type not in allowed:
                raise local_error(f"{kind.name} reply cannot carry {rtde_type!r}")
        body = ",".join(answers).encode("ascii")
        if recipe_id is None:
            return request, in_order, answers, body
        if not isinstance(recipe_id, int) or not 0 <= recipe_id <= 0xFF:
            raise local_error(f"recipe id {recipe_id!r} is not a uint8")
        return request, in_order, answers, U8.pack(recipe_id) + body

    def _send_outputs_answer(self, message: OutputsSetup) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        recipe_id = message.recipe_id
        if (recipe_id is None) != (self._version == 1):
            raise local_error("an output recipe id goes with protocol v2 only (None under v1)")
        request, in_order, types, payload = self._setup_answer(kind, recipe_id, message.types, OUTPUT_ANSWERS)
        found = NOT_FOUND not in types
        recipe = Recipe(request.names, types) if found else None
        outcome = Step.OUTPUTS_CONFIGURED if found else Step.OUTPUTS_NOT_FOUND
        self._answer(kind, payload, outcome, in_order)
        if in_order or found:  # an out-of-order failed setup keeps the recipe that streams now
            self._output_recipe, self._output_recipe_id = recipe, recipe_id if found else None

    def _send_inputs_answer(self, message: InputsSetup) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        if message.recipe_id is None:
            raise local_error("SETUP_INPUTS reply needs a recipe id (every protocol version)")
        request, in_order, types, payload = self._setup_answer(
            kind, message.recipe_id, message.types, INPUT_ANSWERS
        )
        usable = NOT_FOUND not in types and IN_USE not in types
        self._answer(kind, payload, Step.INPUTS_ANSWERED, in_order)
        if usable:
            self._input_recipes[message.recipe_id] = Recipe(request.names, types)
            self._input_recipe_id = message.recipe_id

    def _send_start_answer(self, message: StartAccept) -> None:
        kind = PackageType.CONTROL_PACKAGE_START
        _, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        if accepted and self._output_recipe is None:
            raise local_error("START accepted without an output recipe; a controller answers accepted=False")
        outcome = Step.START_ACCEPTED if accepted else Step.START_REFUSED
        self._answer(kind, U8.pack(accepted), outcome, in_order)

    def _send_pause_answer(self, message: PauseAccept) -> None:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        _, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        outcome = Step.PAUSE_ACCEPTED if accepted else Step.PAUSE_REFUSED
        self._answer(kind, U8.pack(accepted), outcome, in_order)

    def _send_output_data(self, message: OutputData) -> None:
        state = self._next(Step.OUTPUT_DATA, local=True)
        recipe = self._output_recipe
        if recipe is None:
            raise local_error("output data without an output recipe")
        try:
            body = recipe.encode(message.values)
        except ValueError as err:
            raise local_error(f"output data: {err}") from err
        if self._version >= 2:
            assert self._output_recipe_id is not None  # v2 setups always carry one
            body = U8.pack(self._output_recipe_id) + body
        self._emit(PackageType.DATA_PACKAGE, body)
        self._state = state
