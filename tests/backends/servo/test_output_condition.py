"""output_condition: a servo arm's lifecycle and the reason users read, from its outputs' reports."""

from __future__ import annotations

import pytest

from urdaemon.backends.servo.backend import output_condition
from urdaemon.backends.servo.writer import OutputReport
from urdaemon.model import Lifecycle

USB = "serial /dev/serial/by-id/usb-ssc32"
I2C = "i2c bus 1 (0x40, 0x41)"
GONE = "could not open port /dev/serial/by-id/usb-ssc32: [Errno 2] No such file or directory"
EIO = "write failed: [Errno 5] Input/output error"
NACK = "Remote I/O error (errno 121)"


def report(label: str, state: str, error: str = "", retry_in_s: float = 0.0) -> OutputReport:
    """A report with counters that play no part in the condition."""
    return OutputReport(label, state, error, retry_in_s, 7, 9, 1, 0, 0)


@pytest.mark.parametrize(
    ("reports", "lifecycle", "wanted"),
    [
        pytest.param([], Lifecycle.RUNNING, [], id="zenoh only: nothing to wait for"),
        pytest.param([report(USB, "ok")], Lifecycle.RUNNING, [], id="ok"),
        pytest.param([report(USB, "ok"), report(I2C, "ok")], Lifecycle.RUNNING, [], id="all ok"),
        pytest.param(
            [report(USB, "connecting")],
            Lifecycle.CONNECTING,
            [f"opening servo output {USB}"],
            id="opening the first time",
        ),
        pytest.param(
            [report(USB, "connecting", GONE, 1.04)],
            Lifecycle.CONNECTING,
            [f"opening servo output {USB}: {GONE}", "trying again in 1.0 s"],
            id="opening failed",
        ),
        pytest.param(
            [report(USB, "lost", EIO, 0.1)],
            Lifecycle.DISCONNECTED,
            [f"servo output {USB} failed: {EIO}", "opening it again in 0.1 s"],
            id="lost",
        ),
        pytest.param(
            [report(I2C, "ok"), report(USB, "lost", EIO, 0.25)],
            Lifecycle.DISCONNECTED,
            [USB, EIO],
            id="one of two lost",
        ),
        pytest.param(
            [report(USB, "lost", EIO, 0.1), report(I2C, "lost", NACK, 2.0)],
            Lifecycle.DISCONNECTED,
            [USB, EIO],
            id="two lost: the first named",
        ),
        pytest.param(
            [report(I2C, "connecting", NACK, 5.0), report(USB, "lost", EIO, 0.1)],
            Lifecycle.DISCONNECTED,
            [f"servo output {USB} failed: {EIO}", "opening it again in 0.1 s"],
            id="one lost, one never opened: the failure first",
        ),
        pytest.param(
            [report(I2C, "ok"), report(USB, "stopped")],
            Lifecycle.DISCONNECTED,
            [f"servo output {USB} stopped"],
            id="stopped",
        ),
    ],
)
def test_the_condition_follows_the_outputs(
    reports: list[OutputReport], lifecycle: Lifecycle, wanted: list[str]
) -> None:
    got, reason = output_condition(reports)
    assert got is lifecycle
    if not wanted:
        assert reason == "", "a working arm has nothing to explain"
    for part in wanted:
        assert part in reason, f"{part!r} not in {reason!r}"
    for working in (r.label for r in reports if r.state == "ok"):
        assert working not in reason, "only the outputs that do not work are named"
