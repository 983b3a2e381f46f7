"""OutputWriter: the thread between a servo arm's cycle and a blocking board link. The links here are
fakes the test sequences with events: nothing sleeps, every wait is bounded."""

from __future__ import annotations

import errno
import threading
from collections.abc import Callable, Iterator, Sequence

import pytest

from urdaemon.backends.servo.writer import OutputWriter

WAIT_S = 5.0
"""The longest any step may take before the test counts it as never happening."""

Call = tuple[str, tuple[float, ...] | None]

A, B, C, D = (1500.0, 1600.0), (1510.0, 1600.0), (1520.0, 1610.0), (1530.0, 1620.0)


class FakeLink:
    """A BoardLink that records its calls, fails where it is told to, and can hold a call (the
    n-th of a kind, counted from 1) until the test lets it go."""

    label = "fake board"

    def __init__(
        self,
        *,
        open_errors: Sequence[OSError | None] = (),
        write_errors: Sequence[OSError | None] = (),
        off_error: OSError | None = None,
        always_fail_open: OSError | None = None,
        check_errors: Sequence[Exception | None] = (),
    ) -> None:
        self.calls: list[Call] = []
        self.holds: dict[tuple[str, int], threading.Event] = {}
        self.held_too_long = False
        self._open_errors = list(open_errors)
        self._write_errors = list(write_errors)
        self._off_error = off_error
        self._check_errors = list(check_errors)
        self._always_fail_open = always_fail_open
        self._changed = threading.Condition()

    def hold(self, kind: str, number: int) -> threading.Event:
        """Make the ``number``-th call of ``kind`` wait until the returned event is set."""
        event = self.holds[(kind, number)] = threading.Event()
        return event

    def wait_for(self, what: Callable[[list[Call]], bool], why: str) -> None:
        """Wait (bounded) until the calls so far satisfy ``what``."""
        with self._changed:
            assert self._changed.wait_for(lambda: what(self.calls), WAIT_S), f"{why}; calls: {self.calls}"

    def count(self, kind: str) -> int:
        """How many calls of ``kind`` were made so far."""
        with self._changed:
            return sum(1 for name, _ in self.calls if name == kind)

    def writes(self) -> list[tuple[float, ...] | None]:
        """The frames of the write calls, in order."""
        with self._changed:
            return [frame for name, frame in self.calls if name == "write"]

    def _record(self, kind: str, frame: tuple[float, ...] | None = None) -> None:
        with self._changed:
            self.calls.append((kind, frame))
            number = sum(1 for name, _ in self.calls if name == kind)
            self._changed.notify_all()
        gate = self.holds.get((kind, number))
        if gate is not None and not gate.wait(WAIT_S):
            self.held_too_long = True

    def open(self) -> None:
        """Open (or fail as scripted)."""
        self._record("open")
        if self._always_fail_open is not None:
            raise self._always_fail_open
        error = self._open_errors.pop(0) if self._open_errors else None
        if error is not None:
            raise error

    def write(self, pulses: Sequence[float]) -> int:
        """Take a frame (or fail as scripted); one transfer per pulse."""
        self._record("write", tuple(pulses))
        error = self._write_errors.pop(0) if self._write_errors else None
        if error is not None:
            raise error
        return len(pulses)

    def check(self) -> None:
        """Say the device is there (or fail as scripted)."""
        self._record("check")
        error = self._check_errors.pop(0) if self._check_errors else None
        if error is not None:
            raise error

    def off(self) -> None:
        """Stop the pulses (or fail as scripted)."""
        self._record("off")
        if self._off_error is not None:
            raise self._off_error

    def close(self) -> None:
        """Release the device."""
        self._record("close")


def constant_clock() -> float:
    """A clock that stands still: ``retry_in_s`` is then exactly the backoff."""
    return 100.0


@pytest.fixture
def writers() -> Iterator[list[tuple[OutputWriter, FakeLink]]]:
    """Writers a test started: stopped at the end whatever happened (every hold let go first)."""
    started: list[tuple[OutputWriter, FakeLink]] = []
    yield started
    for writer, link in started:
        for gate in link.holds.values():
            gate.set()
        writer.stop(False)
        assert not link.held_too_long, "the test never let a held call go"


def start(
    writers: list[tuple[OutputWriter, FakeLink]],
    link: FakeLink,
    retry_s: Sequence[float] = (0.001,),
    probe_every_s: float = 60.0,
    first: Sequence[float] | None = None,
) -> OutputWriter:
    """A writer on ``link``, started (with ``first`` submitted before its thread starts, if given)."""
    writer = OutputWriter(link, retry_s=retry_s, probe_every_s=probe_every_s, clock=constant_clock)
    writers.append((writer, link))
    if first is not None:
        writer.submit(first)
    writer.start()
    return writer


def test_a_slow_device_gets_only_the_newest_frame(writers: list[tuple[OutputWriter, FakeLink]]) -> None:
    link = FakeLink()
    first_write = link.hold("write", 1)
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the first frame is being written")
    for frame in (B, C, D):
        writer.submit(frame)  # never waits for the device
    assert writer.report().superseded == 2, "B and C were replaced before the device took them"
    first_write.set()
    link.wait_for(lambda calls: ("write", D) in calls, "the newest frame is written next")
    writer.stop(False)
    assert link.writes() == [A, D]
    report = writer.report()
    assert (report.frames, report.transfers, report.superseded) == (2, 4, 2)
    assert (report.failures, report.reopened) == (0, 0)


def test_an_output_that_cannot_be_opened_is_connecting_until_it_opens(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    missing = OSError(errno.ENOENT, "No such file or directory")
    denied = OSError(errno.EACCES, "Permission denied")
    link = FakeLink(open_errors=[missing, missing, denied])
    fourth_open = link.hold("open", 4)
    writer = OutputWriter(link, retry_s=(0.001, 0.002, 0.003), clock=constant_clock)
    assert (writer.report().state, writer.changes) == ("connecting", 0)
    writers.append((writer, link))
    writer.start()
    link.wait_for(lambda calls: sum(name == "open" for name, _ in calls) == 4, "opened again after failing")
    report = writer.report()
    assert report.state == "connecting"
    assert report.error == "Permission denied (errno 13)"
    assert report.retry_in_s == pytest.approx(0.003), "the third attempt's backoff"
    assert report.failures == 3
    assert writer.changes == 3, 'each failure is a change: the reason\'s "again in" follows the backoff'
    assert link.count("close") == 3, "a failed open leaves nothing open"
    fourth_open.set()
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the frame is written once open")
    report = writer.report()
    assert (report.state, report.error, report.retry_in_s) == ("ok", "", 0.0)
    assert writer.changes == 4, "three failures, then ok"
    assert report.reopened == 0, "the first open is no reopening"


def test_a_failed_write_closes_the_output_and_opens_it_again(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(write_errors=[None, OSError(errno.EIO, "Input/output error")])
    second_open = link.hold("open", 2)
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the first frame is written")
    writer.submit(B)
    link.wait_for(lambda calls: sum(name == "open" for name, _ in calls) == 2, "opened again after a backoff")
    report = writer.report()
    assert report.state == "lost"
    assert report.error == "Input/output error (errno 5)"
    assert report.retry_in_s == pytest.approx(0.001)
    assert (report.failures, report.frames) == (1, 1)
    assert writer.changes == 2, "ok, then lost (the failure)"
    assert link.calls[-2:] == [("close", None), ("open", None)], "closed before opening again"
    writer.submit(C)  # the arm goes on while the device is away
    second_open.set()
    link.wait_for(lambda calls: ("write", C) in calls, "the newest frame follows the reopening")
    report = writer.report()
    assert (report.state, report.error, report.reopened) == ("ok", "", 1)
    assert writer.changes == 3
    assert link.writes()[-1] == C


def test_a_reopened_output_gets_the_last_frame_again(writers: list[tuple[OutputWriter, FakeLink]]) -> None:
    link = FakeLink(write_errors=[None, OSError(errno.EIO, "Input/output error")])
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the first frame is written")
    writer.submit(A)  # the same pulses again (the writer does not compare): this write fails
    link.wait_for(lambda calls: len(calls) >= 6, "reopened and written")
    # nothing newer to write: the board may have been reset, so it gets where the arm is again
    assert link.calls == [
        ("open", None),
        ("write", A),
        ("write", A),
        ("close", None),
        ("open", None),
        ("write", A),
    ]
    writer.stop(False)
    report = writer.report()
    assert (report.failures, report.reopened) == (1, 1)


def test_after_a_failed_write_the_reopened_output_gets_that_frame(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(write_errors=[None, OSError(errno.EIO, "Input/output error")])
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the first frame is written")
    writer.submit(B)  # fails; the arm stops here (a goal aborted): no newer frame follows
    link.wait_for(lambda calls: len(calls) >= 6, "reopened and written")  # open A B close open <write>
    # the first write after reopening puts the newest frame on the board: the frame it held before
    # the failure would move the servos back to where the arm no longer is
    assert link.calls[4:6] == [("open", None), ("write", B)], "the board must show where the arm is"


def test_stop_with_off_stops_the_pulses_then_closes(writers: list[tuple[OutputWriter, FakeLink]]) -> None:
    link = FakeLink()
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the frame is written")
    writer.stop(True)
    assert link.calls[-2:] == [("off", None), ("close", None)]
    report = writer.report()
    assert (report.state, report.error) == ("stopped", "")
    assert writer.changes == 2, "ok, then stopped"


def test_stop_without_off_leaves_the_pulses_and_closes(writers: list[tuple[OutputWriter, FakeLink]]) -> None:
    link = FakeLink()
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the frame is written")
    writer.stop(False)
    assert link.calls[-1] == ("close", None)
    assert link.count("off") == 0
    assert writer.report().state == "stopped"


def test_an_off_that_fails_is_counted_and_the_output_still_closes(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(off_error=OSError(errno.EIO, "Input/output error"))
    writer = start(writers, link)
    writer.submit(A)
    link.wait_for(lambda calls: ("write", A) in calls, "the frame is written")
    writer.stop(True)
    assert link.calls[-2:] == [("off", None), ("close", None)]
    report = writer.report()
    assert (report.state, report.error, report.failures) == ("stopped", "Input/output error (errno 5)", 1)


def test_stop_while_the_device_fails_ends_without_waiting_out_the_backoff(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(always_fail_open=OSError(errno.ENOENT, "No such file or directory"))
    writer = start(writers, link, retry_s=(600.0,))
    link.wait_for(lambda calls: ("close", None) in calls, "the first open failed")
    ended = threading.Event()

    def stop_it() -> None:
        writer.stop(True)
        ended.set()

    threading.Thread(target=stop_it, name="stopping the writer", daemon=True).start()
    assert ended.wait(WAIT_S), "stop waited for the 600 s backoff"
    assert link.count("open") == 1
    assert link.count("off") == 0, "nothing is open to switch off"
    assert link.calls[-1] == ("close", None)
    report = writer.report()
    assert (report.state, report.error) == ("stopped", "No such file or directory (errno 2)")


def test_an_idle_output_is_probed_and_a_failed_probe_reopens_it_with_the_last_frame(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(check_errors=[None, OSError(121, "Remote I/O error")])
    # the frame is there before the thread starts: opening writes it, and only then may the output
    # be idle (submitted after the start, a thread that opened the device and waited its 10 ms
    # before the test's thread ran again probed first)
    writer = start(writers, link, probe_every_s=0.01, first=(1500.0, 1600.0))
    link.wait_for(lambda calls: calls.count(("open", None)) == 2, "probed, failed, opened again")
    link.wait_for(lambda calls: calls[-1] == ("write", (1500.0, 1600.0)), "the frame written again")
    kinds = [name for name, _ in link.calls]
    assert kinds[:5] == ["open", "write", "check", "check", "close"]
    report = writer.report()
    assert (report.failures, report.reopened) == (1, 1)
    assert report.frames == 2  # the write after reopening is a frame put on the device too


def test_a_bug_in_a_link_is_reported_and_does_not_end_the_thread(
    writers: list[tuple[OutputWriter, FakeLink]],
) -> None:
    link = FakeLink(write_errors=[ValueError("block of 36 bytes")])  # type: ignore[list-item]
    writer = start(writers, link)
    changes = writer.changes
    writer.submit((1500.0,))
    link.wait_for(lambda calls: calls.count(("open", None)) == 2, "opened again after the bug")
    link.wait_for(lambda calls: calls[-1] == ("write", (1500.0,)), "the frame written again")
    assert writer.changes > changes
    assert writer.report().failures == 1
