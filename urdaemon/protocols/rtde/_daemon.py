"""The daemon's side of RTDE: send requests and input data, decode the replies and the output data."""

from __future__ import annotations

import math
from collections.abc import Sequence

from urdaemon.protocols.rtde._core import RtdeCore
from urdaemon.protocols.rtde._events import (
    ControllerVersion,
    DataPackage,
    GetControllerVersion,
    InputData,
    InputsConfigured,
    OutputsConfigured,
    Pause,
    PauseReply,
    ProtocolVersionReply,
    RequestProtocolVersion,
    SendText,
    SetupInputs,
    SetupOutputs,
    Start,
    StartReply,
)
from urdaemon.protocols.rtde._recipe import INPUT_ANSWERS, OUTPUT_ANSWERS, Recipe
from urdaemon.protocols.rtde._state import REQUEST_STEPS, TRANSITIONS, Request, Step
from urdaemon.protocols.rtde._wire import (
    E_SERIES_MAX_FREQUENCY_HZ,
    F64,
    MAX_RECIPE_NAMES_BYTES,
    SUPPORTED_PROTOCOL_VERSIONS,
    U8,
    U16,
    VERSION4,
    Buf,
    PackageType,
    local_error,
    max_frequency,
)
from urdaemon.protocols.rtde_variables import IN_USE, NOT_FOUND

__all__ = ["DaemonSide"]


class DaemonSide(RtdeCore):
    """The daemon's job: send requests and input data, decode the replies and the output data."""

    def _daemon_tables(self) -> None:
        P = PackageType
        self._handlers = {
            P.REQUEST_PROTOCOL_VERSION: self._on_version_reply,
            P.GET_URCONTROL_VERSION: self._on_controller_version,
            P.CONTROL_PACKAGE_SETUP_OUTPUTS: self._on_outputs_reply,
            P.CONTROL_PACKAGE_SETUP_INPUTS: self._on_inputs_reply,
            P.CONTROL_PACKAGE_START: self._on_start_reply,
            P.CONTROL_PACKAGE_PAUSE: self._on_pause_reply,
            P.DATA_PACKAGE: self._on_output_data,
            P.TEXT_MESSAGE: self._on_text_from_robot,
        }
        self._senders = {
            RequestProtocolVersion: self._send_version_request,
            GetControllerVersion: self._send_controller_version_request,
            SetupOutputs: self._send_setup_outputs,
            SetupInputs: self._send_setup_inputs,
            Start: self._send_start,
            Pause: self._send_pause,
            InputData: self._send_input_data,
            SendText: self._send_text,
        }

    # -- DAEMON: requests ------------------------------------------------------------------------

    def _request(self, kind: PackageType, payload: bytes, request: Request | None = None) -> None:
        if self._requests:
            due = self._requests[0].kind.name
            raise local_error(f"{kind.name} while the {due} reply is still due (one request at a time)")
        step = REQUEST_STEPS[kind]
        state = self._state if step is None else self._next(step, local=True)
        self._emit(kind, payload)
        self._state = state
        self._requests.append(request or Request(kind))

    def _send_version_request(self, message: RequestProtocolVersion) -> None:
        version = message.version
        if version not in SUPPORTED_PROTOCOL_VERSIONS:
            raise local_error(
                f"this codec speaks RTDE protocol versions {SUPPORTED_PROTOCOL_VERSIONS}, not {version!r}"
            )
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        self._request(kind, U16.pack(version), Request(kind, version=version))

    def _send_controller_version_request(self, message: GetControllerVersion) -> None:
        self._request(PackageType.GET_URCONTROL_VERSION, b"")

    def _send_setup_outputs(self, message: SetupOutputs) -> None:
        names = _names_payload(message.names)
        frequency = message.frequency
        if self._version == 1:
            if frequency is not None:
                raise local_error(
                    "protocol v1 SETUP_OUTPUTS has no frequency (the robot streams at its rate)"
                )
            payload = names
        else:
            known = self._controller_version
            limit = max_frequency(known.major) if known else E_SERIES_MAX_FREQUENCY_HZ
            if not isinstance(frequency, int | float) or not (
                math.isfinite(frequency) and 0 < frequency <= limit
            ):
                raise local_error(f"output frequency {frequency!r} Hz is not in (0, {limit}]")
            payload = F64.pack(frequency) + names
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        self._request(kind, payload, Request(kind, names=tuple(message.names)))

    def _send_setup_inputs(self, message: SetupInputs) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        self._request(kind, _names_payload(message.names), Request(kind, names=tuple(message.names)))

    def _send_start(self, message: Start) -> None:
        self._request(PackageType.CONTROL_PACKAGE_START, b"")

    def _send_pause(self, message: Pause) -> None:
        self._request(PackageType.CONTROL_PACKAGE_PAUSE, b"")

    def _send_input_data(self, message: InputData) -> None:
        recipe_id = self._input_recipe_id if message.recipe_id is None else message.recipe_id
        recipe = None if recipe_id is None else self._input_recipes.get(recipe_id)
        if recipe_id is None or recipe is None:
            raise local_error(f"input data for input recipe {recipe_id}, which the robot never set up")
        state = self._next(Step.INPUT_DATA, local=True)
        try:
            body = recipe.encode(message.values)
        except ValueError as err:
            raise local_error(f"input data: {err}") from err
        self._emit(PackageType.DATA_PACKAGE, U8.pack(recipe_id) + body)
        self._state = state

    # -- DAEMON: replies and data ----------------------------------------------------------------

    def _reply_to(self, kind: PackageType) -> Request:
        """The request this reply answers; a reply nobody asked for is the robot's error."""
        if not self._requests or self._requests[0].kind is not kind:
            due = self._requests[0].kind.name if self._requests else "no reply"
            raise self._bad(f"{kind.name} reply while {due} is due")
        return self._requests.popleft()

    def _on_version_reply(self, buf: Buf, start: int, end: int) -> ProtocolVersionReply:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        request = self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(Step.VERSION_ACCEPTED if accepted else Step.VERSION_REFUSED, local=False)
        if accepted:
            self._version = request.version
        return ProtocolVersionReply(accepted)

    def _on_controller_version(self, buf: Buf, start: int, end: int) -> ControllerVersion:
        self._reply_to(PackageType.GET_URCONTROL_VERSION)
        if end - start != VERSION4.size:
            raise self._bad(f"GET_URCONTROL_VERSION reply has {end - start} payload bytes, expected 16")
        self._controller_version = ControllerVersion(*VERSION4.unpack_from(buf, start))
        return self._controller_version

    def _on_outputs_reply(self, buf: Buf, start: int, end: int) -> OutputsConfigured:
        request = self._reply_to(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS)
        recipe_id: int | None = None
        if self._version >= 2:
            if end <= start:
                raise self._bad("SETUP_OUTPUTS reply without its recipe id")
            recipe_id = buf[start]
            start += 1
        types = self._types(buf, start, end, len(request.names), OUTPUT_ANSWERS)
        not_found = tuple(name for name, t in zip(request.names, types, strict=True) if t == NOT_FOUND)
        if not_found:
            self._state = self._next(Step.OUTPUTS_NOT_FOUND, local=False)
            self._output_recipe, self._output_recipe_id = None, None
        else:
            self._state = self._next(Step.OUTPUTS_CONFIGURED, local=False)
            self._output_recipe, self._output_recipe_id = Recipe(request.names, types), recipe_id
        return OutputsConfigured(recipe_id, types, not_found)

    def _on_inputs_reply(self, buf: Buf, start: int, end: int) -> InputsConfigured:
        request = self._reply_to(PackageType.CONTROL_PACKAGE_SETUP_INPUTS)
        if end <= start:
            raise self._bad("SETUP_INPUTS reply without its recipe id")
        recipe_id = buf[start]
        types = self._types(buf, start + 1, end, len(request.names), INPUT_ANSWERS)
        pairs = tuple(zip(request.names, types, strict=True))
        not_found = tuple(name for name, t in pairs if t == NOT_FOUND)
        in_use = tuple(name for name, t in pairs if t == IN_USE)
        self._state = self._next(Step.INPUTS_ANSWERED, local=False)
        if not not_found and not in_use:
            self._input_recipes[recipe_id] = Recipe(request.names, types)
            self._input_recipe_id = recipe_id
        return InputsConfigured(recipe_id, types, not_found, in_use)

    def _on_start_reply(self, buf: Buf, start: int, end: int) -> StartReply:
        kind = PackageType.CONTROL_PACKAGE_START
        self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(Step.START_ACCEPTED if accepted else Step.START_REFUSED, local=False)
        return StartReply(accepted)

    def _on_pause_reply(self, buf: Buf, start: int, end: int) -> PauseReply:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(Step.PAUSE_ACCEPTED if accepted else Step.PAUSE_REFUSED, local=False)
        return PauseReply(accepted)

    def _on_output_data(self, buf: Buf, start: int, end: int) -> DataPackage:
        # the 500 Hz path: one table lookup, one size check, one unpack_from
        recipe = self._output_recipe
        if (self._state, Step.OUTPUT_DATA) not in TRANSITIONS or recipe is None:
            raise self._bad(f"DATA_PACKAGE in state {self._state.name}, before outputs were started")
        if self._version == 1:
            if end - start != recipe.size:
                raise self._bad(
                    f"DATA_PACKAGE payload of {end - start} bytes, output recipe is {recipe.size}"
                )
            return DataPackage(None, recipe.decode(buf, start))
        if end - start != recipe.size + 1:
            raise self._bad(
                f"DATA_PACKAGE payload of {end - start} bytes, expected 1 (id) + {recipe.size} (recipe)"
            )
        recipe_id = buf[start]
        if recipe_id != self._output_recipe_id:
            raise self._bad(
                f"DATA_PACKAGE for output recipe {recipe_id}, configured is {self._output_recipe_id}"
            )
        return DataPackage(recipe_id, recipe.decode(buf, start + 1))


def _names_payload(names: Sequence[str]) -> bytes:
    """A SETUP_* name list for the wire; LocalProtocolError if a controller could not read it."""
    if isinstance(names, str) or not names:
        raise local_error("a recipe needs a non-empty sequence of variable names")
    for name in names:
        if not isinstance(name, str) or not name or not name.isascii() or "," in name:
            raise local_error(f"RTDE variable names are non-empty ASCII without commas, not {name!r}")
    joined = ",".join(names).encode("ascii")
    if len(joined) > MAX_RECIPE_NAMES_BYTES:
        raise local_error(f"name list of {len(joined)} bytes exceeds the {MAX_RECIPE_NAMES_BYTES}-byte limit")
    return joined
