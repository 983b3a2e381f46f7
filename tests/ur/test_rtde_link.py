"""The daemon's RTDE link against the fake controller: handshake, the robot as the clock, inputs."""

from __future__ import annotations

import asyncio
import itertools
from typing import Any

import pytest

from tests.helpers import fake_address
from urdaemon.backends.ur.rtde_link import RtdeLink, StateMapper, input_recipe, output_recipe
from urdaemon.errors import ConnectionLostError, RemoteProtocolError
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import UR_JOINTS, Lifecycle, RobotMode, RobotState, SafetyMode

pytestmark = pytest.mark.timeout(60)


def _lifecycle(state: RobotState) -> Lifecycle:
    """Read through a call: the type checker must not pin a field the link changes behind its back."""
    return state.lifecycle


async def test_handshake_streams_the_standard_recipe_and_maps_it_into_the_state() -> None:
    fake = FakeController("ur10e", address=fake_address(), powered=True)
    await fake.start()
    try:
        state = RobotState.zeros(UR_JOINTS)
        names = output_recipe()
        mapper = StateMapper(names)
        hundred = asyncio.Event()
        stamps: list[float] = []

        def on_package(values: tuple[Any, ...]) -> None:
            mapper.apply(values, state)
            stamps.append(state.controller_time)
            if len(stamps) == 100:
                hundred.set()

        link = await RtdeLink.connect(fake.address, on_package)
        configured = await link.handshake(names, input_recipe())
        assert configured.types[0] == "DOUBLE"
        assert link.frequency == 500.0
        assert link.controller_version is not None
        assert link.controller_version.major == 5
        await link.start()
        await asyncio.wait_for(hundred.wait(), 10.0)
        assert {round(b - a, 6) for a, b in itertools.pairwise(stamps[:100])} == {0.002}
        assert state.positions == pytest.approx(fake.arm.q, abs=1e-9)
        assert state.robot_mode is RobotMode.RUNNING
        assert state.safety_mode is SafetyMode.NORMAL
        assert state.lifecycle is Lifecycle.RUNNING
        assert state.program_running is False
        assert state.ready_for_motion is False, "brakes released but no control program: not ready"
        assert state.not_ready_reason().startswith("control program is not running")
        fake.protective_stop()
        # each cycle's package reaches the link between two cycles: a few cycles suffice
        await fake.until(lambda: _lifecycle(state) is Lifecycle.PROTECTIVE_STOP, cycles=500)
        assert _lifecycle(state) is Lifecycle.PROTECTIVE_STOP
        # the input recipe: set the speed slider and digital output 2
        values = dict.fromkeys(input_recipe(), 0)
        values.update(speed_slider_mask=1, standard_digital_output_mask=1 << 2, standard_digital_output=0xFF)
        doubles = {
            "speed_slider_fraction": 0.4,
            "standard_analog_output_0": 0.0,
            "standard_analog_output_1": 0.0,
        }
        link.send_inputs([doubles.get(n, values[n]) for n in input_recipe()])
        await fake.until(
            lambda: state.digital_out[2] and state.speed_slider == pytest.approx(0.4), cycles=500
        )
        assert state.digital_out[2] is True
        assert state.speed_slider == pytest.approx(0.4)
        link.close()
        error = await asyncio.wait_for(link.closed, 5.0)
        assert isinstance(error, ConnectionLostError)
    finally:
        await fake.close()


async def test_a_cb3_controller_streams_at_125_hz() -> None:
    fake = FakeController("ur5", address=fake_address(), controller_version=(3, 15, 7, 0))
    await fake.start()
    try:
        link = await RtdeLink.connect(fake.address, lambda values: None)
        await link.handshake(output_recipe(), None)
        assert link.frequency == 125.0
        link.close()
    finally:
        await fake.close()


async def test_unknown_outputs_and_a_vanishing_robot_are_errors_with_reasons() -> None:
    fake = FakeController("ur10e", address=fake_address())
    await fake.start()
    try:
        link = await RtdeLink.connect(fake.address, lambda values: None)
        with pytest.raises(RemoteProtocolError, match="does not know output\\(s\\) no_such_output"):
            await link.handshake(("timestamp", "actual_q", "actual_qd", "no_such_output"), None)
        link.close()
        link = await RtdeLink.connect(fake.address, lambda values: None)
        await link.handshake(output_recipe(), None)
        await link.start()
        fake.drop("rtde")
        error = await asyncio.wait_for(link.closed, 5.0)
        assert isinstance(error, ConnectionLostError)
    finally:
        await fake.close()
    with pytest.raises(ConnectionLostError, match="cannot connect"):
        await RtdeLink.connect(fake.address, lambda values: None)


async def test_packages_that_queued_up_are_delivered_in_order_all_but_the_newest_catching_up() -> None:
    fake = FakeController("ur10e", address=fake_address(), powered=True)
    await fake.start()
    try:
        state = RobotState.zeros(UR_JOINTS)
        mapper = StateMapper(output_recipe())
        stamps: list[tuple[float, bool]] = []  # (controller time, catching up)
        link: RtdeLink | None = None

        def on_package(values: tuple[Any, ...]) -> None:
            mapper.apply(values, state)
            assert link is not None
            stamps.append((state.controller_time, link.catching_up))

        link = await RtdeLink.connect(fake.address, on_package)
        await link.handshake(output_recipe(), input_recipe())
        await link.start()
        await fake.until(lambda: len(stamps) >= 5, cycles=2500)  # streaming: packages in, one by one
        # a busy machine may already have bunched some start-up packages: count this window only
        superseded_before = link.superseded
        assert link.transport is not None
        link.transport.pause_reading()  # the loop is held up: packages queue in the socket
        await fake.cycles_pass(10)
        calls = len(stamps)
        link.transport.resume_reading()
        await fake.until(lambda: len(stamps) > calls + 10, cycles=2500)
        link.close()
        times = [t for t, _ in stamps]
        assert {round(b - a, 6) for a, b in itertools.pairwise(times)} == {0.002}, "every package, in order"
        flags = [catching for _, catching in stamps[calls:]]
        burst = flags.index(False)  # the newest package of the read that brought the backlog
        assert burst >= 9, "the queued packages came in one read, all but its newest catching up"
        assert all(flags[:burst])
        assert link.superseded - superseded_before == burst
        assert link.catching_up is False
    finally:
        await fake.close()


async def test_a_controller_that_speaks_only_protocol_v1_streams_at_its_own_rate() -> None:
    """Reproduction: a controller that refuses RTDE v2 (the fake with ``rtde_versions=(1,)``). The
    handshake fell back to v1 but still put a frequency into SETUP_OUTPUTS, which v1 has no room for:
    the codec refused to send it and the link never came up."""
    fake = FakeController("ur10e", address=fake_address(), powered=True, rtde_versions=(1,))
    await fake.start()
    try:
        count = 0
        fifty = asyncio.Event()

        def on_package(values: tuple[Any, ...]) -> None:
            nonlocal count
            count += 1
            if count == 50:
                fifty.set()

        link = await RtdeLink.connect(fake.address, on_package)
        configured = await link.handshake(output_recipe(), input_recipe(), frequency=125.0)
        assert link.conn.protocol_version == 1
        assert link.frequency == 500.0, "v1 streams at the controller's rate, whatever was asked"
        assert configured.recipe_id is None  # v1 has no recipe ids
        await link.start()
        await asyncio.wait_for(fifty.wait(), 10.0)
        link.close()
    finally:
        await fake.close()
