"""The fake UR controller served on loopback, checked with our own daemon-side codecs and with ur_rtde."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator
from typing import Any

import pytest

from tests.helpers import fake_address
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.controller import FakeController, FakePorts
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.paths import resource_path
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.kinematics_hash import kinematics_hash

pytestmark = pytest.mark.timeout(60)

OUTPUTS = tuple(resource_path("rtde", "output_recipe.txt").read_text().split())
INPUTS = tuple(resource_path("rtde", "input_recipe.txt").read_text().split())


@contextlib.asynccontextmanager
async def fake(**kwargs: Any) -> AsyncIterator[FakeController]:
    """A started fake on a run-specific address (``fake_address``) with the standard ports."""
    controller = FakeController(kwargs.pop("model", "ur10e"), address=fake_address(), **kwargs)
    await controller.start()
    try:
        yield controller
    finally:
        await controller.close()


class Link:
    """A client connection driving one of our sans-IO codecs."""

    def __init__(self, conn: Any, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.conn, self.reader, self.writer = conn, reader, writer
        self.pending: list[Any] = []

    @classmethod
    async def open(cls, conn: Any, address: str, port: int) -> Link:
        reader, writer = await asyncio.open_connection(address, port)
        return cls(conn, reader, writer)

    async def send(self, message: Any) -> None:
        self.conn.send(message)
        self.writer.write(self.conn.data_to_send())
        await self.writer.drain()

    async def next(self, kind: type[Any] | tuple[type[Any], ...] = object, limit: int = 5000) -> Any:
        for _ in range(limit):
            while not self.pending:
                data = await asyncio.wait_for(self.reader.read(65536), 5.0)
                assert data, "the fake closed the connection"
                self.pending += self.conn.receive_data(data)
            event = self.pending.pop(0)
            if isinstance(event, kind):
                return event
        raise AssertionError(f"no {kind} within {limit} events")

    def close(self) -> None:
        self.writer.close()


async def _rtde_session(address: str, frequency: float = 500.0) -> tuple[Link, rtde.OutputsConfigured]:
    link = await Link.open(rtde.RtdeConnection(Side.DAEMON), address, 30004)
    await link.send(rtde.RequestProtocolVersion(2))
    assert (await link.next(rtde.ProtocolVersionReply)).accepted
    await link.send(rtde.GetControllerVersion())
    await link.next(rtde.ControllerVersion)
    await link.send(rtde.SetupOutputs(frequency, OUTPUTS))
    configured = await link.next(rtde.OutputsConfigured)
    return link, configured


async def test_rtde_handshake_serves_the_standard_recipe_at_500_hz() -> None:
    async with fake() as controller:
        link, configured = await _rtde_session(controller.address)
        assert configured.not_found == ()
        assert len(configured.types) == len(OUTPUTS)
        await link.send(rtde.Start())
        assert (await link.next(rtde.StartReply)).accepted
        recipe = link.conn.output_recipe
        assert recipe is not None
        t_index = recipe.index("timestamp")
        stamps = [(await link.next(rtde.DataPackage)).values[t_index] for _ in range(50)]
        steps = {round(b - a, 6) for a, b in itertools.pairwise(stamps)}
        assert steps == {0.002}, steps
        sample = await link.next(rtde.DataPackage)
        values = dict(zip(recipe.names, sample.values, strict=True))
        assert values["robot_mode"] == int(RobotMode.POWER_OFF)
        assert values["safety_mode"] == int(SafetyMode.NORMAL)
        assert values["actual_q"] == pytest.approx(controller.arm.q, abs=1e-9)
        link.close()


async def test_rtde_on_a_cb3_controller_runs_at_125_hz_and_refuses_500() -> None:
    async with fake(model="ur5", controller_version=(3, 15, 7, 0)) as controller:
        link, _ = await _rtde_session(controller.address, 125.0)
        await link.send(rtde.Start())
        await link.next(rtde.StartReply)
        recipe = link.conn.output_recipe
        assert recipe is not None
        t = recipe.index("timestamp")
        a = (await link.next(rtde.DataPackage)).values[t]
        b = (await link.next(rtde.DataPackage)).values[t]
        assert b - a == pytest.approx(0.008)
        link.close()
        link = await Link.open(rtde.RtdeConnection(Side.DAEMON), controller.address, 30004)
        await link.send(rtde.RequestProtocolVersion(2))
        await link.next(rtde.ProtocolVersionReply)
        # ask for 500 Hz without having learnt the version: a CB3 controller refuses the recipe
        await link.send(rtde.SetupOutputs(500.0, ("timestamp",)))
        refused = await link.next(rtde.OutputsConfigured)
        assert refused.recipe_id == 0
        link.close()


async def test_rtde_slower_frequency_is_drift_free() -> None:
    async with fake() as controller:
        link, _ = await _rtde_session(controller.address, 125.0)
        await link.send(rtde.Start())
        await link.next(rtde.StartReply)
        recipe = link.conn.output_recipe
        assert recipe is not None
        t = recipe.index("timestamp")
        stamps = [(await link.next(rtde.DataPackage)).values[t] for _ in range(20)]
        assert {round(b - a, 6) for a, b in itertools.pairwise(stamps)} == {0.008}
        link.close()


async def test_rtde_inputs_change_what_the_outputs_report() -> None:
    async with fake() as controller:
        link, _ = await _rtde_session(controller.address)
        await link.send(rtde.SetupInputs(INPUTS))
        inputs = await link.next(rtde.InputsConfigured)
        assert inputs.not_found == ()
        assert inputs.in_use == ()
        values: dict[str, float] = dict.fromkeys(INPUTS, 0)
        values.update(
            speed_slider_mask=1,
            speed_slider_fraction=0.3,
            standard_digital_output_mask=1 << 3,
            standard_digital_output=0xFF,
            tool_digital_output_mask=1 << 1,
            tool_digital_output=0xFF,
            standard_analog_output_mask=1 << 1,
            standard_analog_output_type=0,
            standard_analog_output_0=0.0,
            standard_analog_output_1=0.4,
        )
        await link.send(rtde.Start())
        await link.next(rtde.StartReply)
        doubles = {"speed_slider_fraction", "standard_analog_output_0", "standard_analog_output_1"}
        await link.send(
            rtde.InputData(tuple(float(values[n]) if n in doubles else int(values[n]) for n in INPUTS))
        )
        recipe = link.conn.output_recipe
        assert recipe is not None
        for _ in range(200):
            sample = dict(zip(recipe.names, (await link.next(rtde.DataPackage)).values, strict=True))
            if sample["target_speed_fraction"] == pytest.approx(0.3):
                break
        assert sample["target_speed_fraction"] == pytest.approx(0.3)
        assert sample["actual_digital_output_bits"] == (1 << 3) | (1 << 17)
        # level 0.4 of the current domain's 4-20 mA, reported in amperes
        assert sample["standard_analog_output1"] == pytest.approx(0.004 + 0.4 * 0.016)
        # a second client cannot own the same inputs
        other, _ = await _rtde_session(controller.address)
        await other.send(rtde.SetupInputs(("speed_slider_mask", "speed_slider_fraction")))
        refused = await other.next(rtde.InputsConfigured)
        assert set(refused.in_use) == {"speed_slider_mask", "speed_slider_fraction"}
        other.close()
        link.close()


async def test_rtde_unknown_output_is_not_found() -> None:
    async with fake() as controller:
        link = await Link.open(rtde.RtdeConnection(Side.DAEMON), controller.address, 30004)
        await link.send(rtde.RequestProtocolVersion(2))
        await link.next(rtde.ProtocolVersionReply)
        await link.send(rtde.SetupOutputs(500.0, ("timestamp", "no_such_variable")))
        configured = await link.next(rtde.OutputsConfigured)
        assert configured.not_found == ("no_such_variable",)
        link.close()


async def test_primary_sends_the_version_then_robot_state_at_10_hz_with_the_kinematics() -> None:
    model = load_ur_model("ur10e")
    async with fake() as controller:
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        version = await link.next(prim.VersionMessage)
        assert (version.project_name, version.major_version, version.minor_version) == ("URControl", 5, 15)
        first = await link.next(prim.RobotState)
        second = await link.next(prim.RobotState)
        modes = [s.get(prim.RobotModeData) for s in (first, second)]
        stamps = [m.timestamp for m in modes if m is not None]
        assert stamps[1] - stamps[0] == pytest.approx(100, abs=4), "10 Hz, in ms of controller time"
        kin = second.get(prim.KinematicsInfo)
        assert kin is not None
        assert kin.kinematics_hash() == model.kinematics_hash
        config = second.get(prim.ConfigurationData)
        assert config is not None
        assert config.robot_type == model.robot_type
        link.close()


async def test_a_calibrated_fake_reports_its_calibration_hash() -> None:
    model = load_ur_model("ur10e")
    dh = model.dh
    calibrated = type(dh)(
        theta=tuple(t + 1e-4 for t in dh.theta), a=dh.a, d=tuple(d + 2e-4 for d in dh.d), alpha=dh.alpha
    )
    async with fake(dh=calibrated) as controller:
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        state = await link.next(prim.RobotState)
        kin = state.get(prim.KinematicsInfo)
        assert kin is not None
        expected = kinematics_hash(calibrated.theta, calibrated.a, calibrated.d, calibrated.alpha)
        assert kin.kinematics_hash() == expected != model.kinematics_hash
        link.close()


async def test_dashboard_bring_up_with_refusals_like_a_real_controller() -> None:
    async with fake() as controller:
        link = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        banner = await link.next(dash.Banner)
        assert banner.is_standard
        await link.send(dash.GetRobotMode())
        assert (await link.next(dash.RobotModeReply)).mode is RobotMode.POWER_OFF
        controller.emergency_stop()
        await link.send(dash.BrakeRelease())
        assert (await link.next(dash.CommandReply)).success is False, "no power-on while e-stopped"
        controller.release_emergency_stop()
        await link.send(dash.Play())
        assert (await link.next(dash.CommandReply)).success is False, "play while powered off is refused"
        await link.send(dash.PowerOn())
        assert (await link.next(dash.CommandReply)).success is True
        # the fake's boot takes 0.5 s of its own clock (250 cycles); then the dashboard says IDLE
        await controller.until(lambda: controller.arm.robot_mode is RobotMode.IDLE, cycles=2500)
        await link.send(dash.GetRobotMode())
        assert (await link.next(dash.RobotModeReply)).mode is RobotMode.IDLE
        await link.send(dash.BrakeRelease())
        assert (await link.next(dash.CommandReply)).success is True
        await controller.until(lambda: controller.arm.robot_mode is RobotMode.RUNNING, cycles=2500)
        await link.send(dash.GetRobotMode())
        assert (await link.next(dash.RobotModeReply)).mode is RobotMode.RUNNING
        await link.send(dash.GetSafetyStatus())
        assert "NORMAL" in (await link.next(dash.SafetyStatusReply)).text
        await link.send(dash.IsInRemoteControl())
        assert (await link.next(dash.RemoteControlReply)).remote is True
        await link.send(dash.GetPolyscopeVersion())
        assert (await link.next(dash.PolyscopeVersionReply)).version[:2] == (5, 15)
        await link.send(dash.GetSerialNumber())
        assert (await link.next(dash.SerialNumberReply)).serial
        await link.send(dash.GetRobotModel())
        assert (await link.next(dash.RobotModelReply)).model == "UR10"
        await link.send(dash.UnlockProtectiveStop())
        assert (await link.next(dash.CommandReply)).success is False
        controller.protective_stop()
        await link.send(dash.GetSafetyMode())
        assert "PROTECTIVE_STOP" in (await link.next(dash.SafetyModeReply)).text
        arm = controller.arm
        await controller.until(lambda: arm.timestamp >= arm.life.unlockable_at, cycles=3000)  # 5 s
        await link.send(dash.UnlockProtectiveStop())
        assert (await link.next(dash.CommandReply)).success is True
        await link.send(dash.Raw("make coffee"))
        assert "make coffee" in (await link.next()).text
        link.close()


async def test_faults_refuse_split_and_drop_connections() -> None:
    faults = FaultInjector(refused={"dashboard"}, split={"rtde"})
    async with fake(faults=faults) as controller:
        reader, writer = await asyncio.open_connection(controller.address, 29999)
        assert await asyncio.wait_for(reader.read(100), 5.0) == b"", "refused: closed at once"
        writer.close()
        # writes split into pieces still decode (the codec reassembles)
        link, configured = await _rtde_session(controller.address)
        assert configured.not_found == ()
        link2 = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await link2.next(prim.VersionMessage)
        assert controller.drop("primary") == 1
        assert await asyncio.wait_for(link2.reader.read(65536 * 4), 5.0) is not None
        link.close()
        link2.close()


async def test_a_stall_pauses_the_streams_and_protective_stop_shows_in_rtde() -> None:
    async with fake(powered=True) as controller:
        link, _ = await _rtde_session(controller.address)
        await link.send(rtde.Start())
        await link.next(rtde.StartReply)
        recipe = link.conn.output_recipe
        assert recipe is not None
        t, mode = recipe.index("timestamp"), recipe.index("safety_mode")
        previous = (await link.next(rtde.DataPackage)).values[t]
        controller.stall(0.2)
        # packages sent before the stall may still be queued for this reader (a loaded machine): the
        # stall shows as one gap of ≥ 0.19 s between consecutive timestamps within the next packages
        gaps = []
        for _ in range(300):
            current = (await link.next(rtde.DataPackage)).values[t]
            gaps.append(current - previous)
            previous = current
            if gaps[-1] >= 0.19:
                break
        assert max(gaps) >= 0.19, "nothing was sent during the stall"
        assert max(gaps) < 0.25, "the stall lasted 0.2 s of controller time"
        controller.protective_stop()
        for _ in range(50):
            sample = await link.next(rtde.DataPackage)
            if sample.values[mode] == int(SafetyMode.PROTECTIVE_STOP):
                break
        assert sample.values[mode] == int(SafetyMode.PROTECTIVE_STOP)
        link.close()


def test_ports_default_to_urs_standard_ports() -> None:
    ports = FakePorts()
    assert (ports.dashboard, ports.primary, ports.secondary, ports.realtime, ports.rtde) == (
        29999,
        30001,
        30002,
        30003,
        30004,
    )
