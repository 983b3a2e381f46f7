"""The dashboard's answers urcl's URSim tests rely on: the operational mode the dashboard sets, and
``load`` of a program in a subdirectory.

urcl's ``operational_mode`` test (e-Series): after ``set operational mode AUTOMATIC`` the controller
says AUTOMATIC, after ``MANUAL`` MANUAL, after ``clear operational mode`` NONE (UR's dashboard guide:
NONE while no mode password is set). Its ``load_program_in_subdir_works`` loads a program by a path
with directories and then waits for ``programState`` = ``STOPPED <file name>``.

Reproduction on the old fake: ``get operational mode`` said NONE whatever was set.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fakeur.test_controller_life import _ask, _dashboard, manual_fake
from urdaemon.protocols import dashboard as dash

pytestmark = pytest.mark.timeout(60)


async def test_the_operational_mode_the_dashboard_sets_is_the_one_it_reports() -> None:
    async with manual_fake() as (controller, _clock):
        link = await _dashboard(controller.address)
        mode = await _ask(link, dash.GetOperationalMode(), dash.OperationalModeReply)
        assert mode.mode is dash.OperationalMode.NONE
        for wanted in (dash.OperationalMode.AUTOMATIC, dash.OperationalMode.MANUAL):
            reply = await _ask(link, dash.SetOperationalMode(wanted), dash.CommandReply)
            assert reply.success, reply.text
            mode = await _ask(link, dash.GetOperationalMode(), dash.OperationalModeReply)
            assert mode.mode is wanted
        reply = await _ask(link, dash.ClearOperationalMode(), dash.CommandReply)
        assert reply.success, reply.text
        mode = await _ask(link, dash.GetOperationalMode(), dash.OperationalModeReply)
        assert mode.mode is dash.OperationalMode.NONE
        link.close()


async def test_a_cb3_has_no_operational_mode() -> None:
    async with manual_fake(model="ur10", controller_version=(3, 15, 7, 0)) as (controller, _clock):
        link = await _dashboard(controller.address)
        reply = await _ask(link, dash.SetOperationalMode(dash.OperationalMode.MANUAL), dash.CommandReply)
        assert not reply.success, reply.text
        link.close()


@pytest.mark.parametrize("name", ["sub/wait_program.script", "{base}/sub/wait_program.script"])
async def test_load_of_a_program_in_a_subdirectory(tmp_path: Path, name: str) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "wait_program.script").write_text("def wait_program():\n  sleep(1.0)\nend\n")
    path = name.format(base=tmp_path)
    async with manual_fake(programs=tmp_path) as (controller, _clock):
        link = await _dashboard(controller.address)
        reply = await _ask(link, dash.Load(path), dash.CommandReply)
        assert reply.success, reply.text
        assert path in reply.text  # urcl: "Loading program: .*<the name it asked for>.*"
        state = await _ask(link, dash.GetProgramState(), dash.ProgramStateReply)
        assert (state.state, state.program) == (dash.ProgramState.STOPPED, "wait_program.script")
        link.close()
