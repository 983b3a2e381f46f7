"""Fixtures of the replay tests: a motion recorded on the mock cell."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integration.conftest import TWO_MOCKS, running_daemon
from tests.replay.recorder import Recorder, record_motion


@pytest.fixture
async def recorded(tmp_path: Path) -> tuple[Path, Path, Recorder]:
    """The cell file, a recording of a motion on it (everything the daemon published, from its own
    session: no sample missing), and what that recording's recorder saw."""
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS)
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        assert daemon.node is not None
        recorder = await record_motion(client, tmp_path / "motion.mcap", daemon.node.session)
    return config, tmp_path / "motion.mcap", recorder
