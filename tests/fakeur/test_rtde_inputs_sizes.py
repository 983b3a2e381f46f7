"""RTDE input packages of another size than their recipe: the fake applies the recipe's fields the
package holds whole, ignores the rest and keeps the client (docs/fake-robot.md, "RTDE inputs, units
and small fixes"), checked at the protocol level and with ur_rtde 1.6.5, which sends such packages."""

from __future__ import annotations

import logging
import struct
from typing import Any

import pytest

from tests.fakeur.judges import fake_robot, pose_off, tcp_pose, wait_until
from tests.fakeur.test_controller import Link, fake
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(120)

INTS = ("input_int_register_0",)
DOUBLES = tuple(f"input_double_register_{i}" for i in range(6))
WATCHED = ("timestamp", "input_int_register_0", "input_int_register_1", *DOUBLES)
"""The output recipe: the input registers as the controller holds them."""


def _package(recipe_id: int, body: bytes) -> bytes:
    """An input DATA_PACKAGE built by hand (our codec only sends packages that fit their recipe)."""
    return struct.pack(">HBB", 4 + len(body), ord("U"), recipe_id) + body


async def _session(address: str, *inputs: tuple[str, ...]) -> tuple[Link, list[int]]:
    """An RTDE client streaming WATCHED, with ``inputs`` set up as input recipes (their ids)."""
    link = await Link.open(rtde.RtdeConnection(Side.DAEMON), address, 30004)
    await link.send(rtde.RequestProtocolVersion(2))
    await link.next(rtde.ProtocolVersionReply)
    await link.send(rtde.SetupOutputs(500.0, WATCHED))
    await link.next(rtde.OutputsConfigured)
    ids = []
    for names in inputs:
        await link.send(rtde.SetupInputs(names))
        ids.append((await link.next(rtde.InputsConfigured)).recipe_id)
    await link.send(rtde.Start())
    assert (await link.next(rtde.StartReply)).accepted
    return link, ids


async def _registers_once(link: Link, done: Any, limit: int = 2000) -> dict[str, Any]:
    """The first output sample for which ``done(sample)`` holds (bounded in samples)."""
    recipe = link.conn.output_recipe
    assert recipe is not None
    for _ in range(limit):
        sample = dict(zip(recipe.names, (await link.next(rtde.DataPackage)).values, strict=True))
        if done(sample):
            return sample
    raise AssertionError(f"no such sample in {limit}")


async def test_a_longer_package_applies_its_recipe_and_keeps_the_client(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """ur_rtde's getForwardKinematics(q, zero TCP): 12 doubles under a recipe of 6."""
    async with fake() as controller:
        link, (recipe,) = await _session(controller.address, INTS + DOUBLES)
        q = (0.5, -1.0, 1.5, -2.0, 2.5, -3.0)
        tail = (9.0,) * 6  # a TCP the recipe has no room for
        with caplog.at_level(logging.INFO, logger="urdaemon.fakeur"):
            for command in (44, 45):
                link.writer.write(_package(recipe, struct.pack(">i12d", command, *q, *tail)))
                await link.writer.drain()
                sample = await _registers_once(link, lambda s, c=command: s["input_int_register_0"] == c)
                assert tuple(sample[name] for name in DOUBLES) == q
        warnings = [r.getMessage() for r in caplog.records if "value bytes" in r.getMessage()]
        assert len(warnings) == 1, warnings  # logged once per size and recipe, both counted
        assert "has 100 value bytes, the recipe 52" in warnings[0]
        assert "applied its first 7 of 7 fields, ignored the bytes after them" in warnings[0]
        assert not [r for r in caplog.records if "dropping client" in r.getMessage()]
        (client,) = controller.rtde.clients
        assert client.odd_inputs == 2
        link.close()


async def test_a_shorter_package_applies_the_fields_it_holds_and_keeps_the_others(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """ur_rtde's setExternalForceTorque: a command and 6 doubles under a recipe with one more int."""
    async with fake() as controller:
        names = INTS + DOUBLES + ("input_int_register_1",)
        link, (recipe,) = await _session(controller.address, names)
        link.writer.write(_package(recipe, struct.pack(">i6di", 1, *(0.0,) * 6, 77)))
        await link.writer.drain()
        await _registers_once(link, lambda s: s["input_int_register_1"] == 77)
        wrench = (1.0, 2.0, 3.0, 0.1, 0.2, 0.3)
        with caplog.at_level(logging.INFO, logger="urdaemon.fakeur"):
            link.writer.write(_package(recipe, struct.pack(">i6d", 55, *wrench)))
            await link.writer.drain()
            sample = await _registers_once(link, lambda s: s["input_int_register_0"] == 55)
        assert tuple(sample[name] for name in DOUBLES) == wrench
        assert sample["input_int_register_1"] == 77  # not in the package: its last value
        (warning,) = [r.getMessage() for r in caplog.records if "value bytes" in r.getMessage()]
        assert "has 52 value bytes, the recipe 56" in warning
        assert "(not written: input_int_register_1)" in warning
        link.close()


def test_ur_rtde_forward_kinematics_with_a_zero_tcp_and_external_force_torque() -> None:
    """ur_rtde 1.6.5 sends both calls' packages at another size than the recipe it names; against a
    controller they work, so they work against the fake (which dropped the client before)."""
    rtde_control = pytest.importorskip("rtde_control")
    with fake_robot("ur10e", "--powered") as fake_process:
        control = rtde_control.RTDEControlInterface(fake_process.address)
        try:
            q = [0.1, -1.2, 1.3, -1.6, -1.5, 0.4]
            # a fresh controller's registers 6..11 (where ur_rtde's script reads the TCP) hold zeros
            assert pose_off(control.getForwardKinematics(q, [0.0] * 6), tcp_pose("ur10e", q)) == ""
            # its command and wrench reach the registers; ur_rtde waits for no answer from its script
            assert control.setExternalForceTorque([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
            logged = wait_until(lambda: "".join(fake_process.log).count("value bytes") == 2, 10.0)
            assert logged, fake_process.log_tail()  # each call's package, logged once
            assert control.isConnected()
            assert control.isProgramRunning()
            assert "dropping client" not in "".join(fake_process.log), fake_process.log_tail()
        finally:
            # no stopScript: ur_rtde's script answers command 55 as done and then waits for a clear that
            # ur_rtde never sends, so its stopScript waits 4 s for "ready"; under load it may even read
            # the "ready" from before 55 and send the stop the script then ignores, waiting for ever
            # (on a controller as on the fake: docs/fake-robot.md, setExternalForceTorque)
            control.disconnect()
