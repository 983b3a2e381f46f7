"""Issue 13 finding 7, the ``ur`` backend's part: cycles the daemon missed or ran late are logged
(rate-limited) like the mock's and the servo's, not only counted in the status."""

from __future__ import annotations

import logging

import pytest

from tests.ur.test_links_harness import program_is_running, ur_run

pytestmark = pytest.mark.timeout(90)


async def test_missed_packages_are_logged_with_counts(caplog: pytest.LogCaptureFixture) -> None:
    """Reproduction: a gap in the RTDE stream counted missed packages in ``cycle_stats`` and the status
    but the log said nothing. Counts are injected as the package handler would add them; the next
    cycle must report them once, with the numbers."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        caplog.set_level(logging.WARNING, logger="urdaemon")
        caplog.clear()
        run.backend._missed += 7
        await run.cycles_pass(3)
        lines = [r.getMessage() for r in caplog.records if "cycles missed" in r.getMessage()]
        assert len(lines) == 1, lines
        assert "7 cycles missed" in lines[0]
        assert "robot 'alice' (ur backend)" in lines[0]
