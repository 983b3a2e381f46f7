"""The daemon's ``analog_out`` is the level 0..1 that ``set_io`` takes, in either domain: the controller
reports a standard analog output in volts (0-10 V) or amperes (4-20 mA), by the domain in
``analog_io_types`` (docs/keys.md, the io row).

Reproduction on the code before: the link copied the controller's volts into ``analog_out``, so
``set_io("analog", 0, 0.5)`` read back 5.0, where docs/keys.md says 0..1.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.fakeur.judges import send_script
from tests.helpers import fake_address
from urdaemon.backends.ur.rtde_link import RtdeLink, StateMapper, input_recipe, output_recipe
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import UR_JOINTS, RobotState

pytestmark = pytest.mark.timeout(60)

DOUBLES = ("speed_slider_fraction", "standard_analog_output_0", "standard_analog_output_1")


async def test_set_io_levels_read_back_as_levels_in_both_domains() -> None:
    fake = FakeController("ur10e", address=fake_address(), powered=True)
    await fake.start()
    try:
        state = RobotState.zeros(UR_JOINTS)
        mapper = StateMapper(output_recipe())

        def on_package(values: tuple[Any, ...]) -> None:
            mapper.apply(values, state)

        link = await RtdeLink.connect(fake.address, on_package)
        await link.handshake(output_recipe(), input_recipe())
        await link.start()
        # what the ur backend's set_io("analog", 0, 0.5) sends (robot_commands.py): voltage domain
        values: dict[str, Any] = dict.fromkeys(input_recipe(), 0)
        values.update(
            standard_analog_output_mask=1,
            standard_analog_output_type=1,
            standard_analog_output_0=0.5,
            standard_analog_output_1=0.0,
            speed_slider_fraction=1.0,
        )
        link.send_inputs([float(values[n]) if n in DOUBLES else values[n] for n in input_recipe()])
        # output 1 in the current domain, set by a script to a quarter of 4-20 mA (8 mA)
        script = "def levels():\n  set_analog_outputdomain(1, 0)\n  set_standard_analog_out(1, 0.25)\nend\n"
        await asyncio.to_thread(send_script, fake.address, 30002, script)
        await fake.until(lambda: fake.arm.io.analog_out[:2] == [0.5, 0.25], cycles=2000)
        then = fake.arm.timestamp  # the controller holds both levels; its next package shows them
        await fake.until(lambda: state.controller_time > then, cycles=500)
        assert state.analog_out == pytest.approx([0.5, 0.25], abs=1e-12)
        link.close()
    finally:
        await fake.close()
