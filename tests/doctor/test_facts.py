"""The facts the doctor gathers, from tables: the host's readers and the clock's arithmetic."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from types import SimpleNamespace

import pytest

from urdaemon.backends.ur.diagnosis import Diagnosis, clock_facts
from urdaemon.doctor.host import host_facts, preempt_rt, sys_nice_capable
from urdaemon.scheduling import RealtimeUnavailable, realtime_request, use_realtime_priority


@pytest.mark.parametrize(
    ("version", "sysfs", "expected"),
    [
        ("#1 SMP PREEMPT_RT Tue Jan 1", None, True),
        ("#1 SMP PREEMPT_DYNAMIC", "1\n", True),
        ("#1 SMP PREEMPT_DYNAMIC", "0\n", False),
        ("#1 SMP PREEMPT_DYNAMIC", None, False),
    ],
)
def test_preempt_rt(version: str, sysfs: str | None, expected: bool) -> None:
    assert preempt_rt(version, sysfs) is expected


@pytest.mark.parametrize(
    ("status", "expected"),
    [
        ("Name:\tpython\nCapEff:\t0000000000000000\n", False),
        ("CapEff:\t0000000000800000\n", True),  # bit 23 only
        ("CapEff:\t000001ffffffffff\n", True),  # root's full set
        ("CapEff:\tzz\n", None),
        ("Name:\tpython\n", None),
        (None, None),
    ],
)
def test_cap_sys_nice(status: str | None, expected: bool | None) -> None:
    assert sys_nice_capable(status) is expected


def test_host_facts_read_the_files_given(tmp_path: Path) -> None:
    (tmp_path / "status").write_text("CapEff:\t0000000000800000\n")
    (tmp_path / "realtime").write_text("1\n")
    facts = host_facts(proc_status=tmp_path / "status", realtime_file=tmp_path / "realtime")
    assert facts["cap_sys_nice"] is True
    assert facts["preempt_rt"] is True
    assert facts["release"] == os.uname().release
    assert facts["loop_policy"] == "SCHED_OTHER"  # the test's thread runs at normal priority
    assert facts["realtime_priority"] == 0
    missing = host_facts(proc_status=tmp_path / "none", realtime_file=tmp_path / "none")
    assert missing["cap_sys_nice"] is None
    assert missing["preempt_rt"] is ("PREEMPT_RT" in os.uname().version)


async def test_a_refused_realtime_request_is_kept_for_its_event_loop_only(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def refuse(pid: int, policy: int, param: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with pytest.raises(RealtimeUnavailable):
        use_realtime_priority(30)
    assert realtime_request() == (30, "Operation not permitted")

    async def elsewhere() -> tuple[int, str | None]:
        return realtime_request()

    assert await asyncio.to_thread(asyncio.run, elsewhere()) == (0, None), "another loop asked nothing"


async def test_the_realtime_request_is_remembered_per_event_loop() -> None:
    assert realtime_request() == (0, None)
    try:
        restore = use_realtime_priority(1)
    except RealtimeUnavailable:
        asked, why = realtime_request()
        assert asked == 1
        assert why
    else:
        assert realtime_request() == (1, None)
        restore()
        assert realtime_request() == (0, None)


CONTROLLER_T0 = 1000.0
HOST_T0 = 1_700_000_000_000_000_000
"""A host time (ns) at controller time 1000 s: the offset is 1_699_999_000 s."""


def _pair(controller_s: float, delay_us: int = 0, drift_ppm: float = 0.0) -> tuple[int, float]:
    elapsed_ns = round((controller_s - CONTROLLER_T0) * 1e9)
    return HOST_T0 + elapsed_ns + round(elapsed_ns * drift_ppm * 1e-6) + delay_us * 1000, controller_s


def test_clock_facts_without_samples() -> None:
    assert clock_facts([], None, 0.002) == {"samples": 0, "period_ms": 2.0, "offset_s": None}
    still = clock_facts([_pair(1060.0)], None, 0.002)  # one package in the window: a stream at rest
    assert still["offset_s"] is None


def test_clock_facts_offset_and_jitter() -> None:
    samples = [_pair(1060.0 + i * 0.002, delay_us) for i, delay_us in enumerate((100, 300, 150, 900))]
    facts = clock_facts(samples, None, 0.002)
    assert facts["samples"] == 4
    assert facts["offset_s"] == pytest.approx(1_699_999_000.0001, abs=1e-6)  # the least delayed
    assert facts["jitter_ms"] == pytest.approx(0.8)
    assert facts["drift_ppm"] is None
    assert facts["baseline_s"] == 0.0


@pytest.mark.parametrize("drift_ppm", [0.0, 50.0, -250.0])
def test_clock_facts_drift_against_the_reference(drift_ppm: float) -> None:
    reference = _pair(CONTROLLER_T0, 100)
    samples = [_pair(1100.0 + i * 0.002, 100 + 10 * (i % 3), drift_ppm) for i in range(50)]
    facts = clock_facts(samples, reference, 0.002)
    assert facts["baseline_s"] == pytest.approx(100.0 * (1 + drift_ppm * 1e-6) + 49 * 0.002, rel=1e-6)
    # the window's smallest offset stands for its whole 0.1 s: within 1 ppm over a 100 s baseline
    assert facts["drift_ppm"] == pytest.approx(drift_ppm, abs=1.0)
    assert facts["drift_bound_ppm"] == pytest.approx(0.2, rel=0.01)  # 20 µs of jitter over 100 s


class _Link:
    packages = 1


def test_the_reference_is_the_pair_that_waited_least_of_the_first_looks_per_link() -> None:
    state = SimpleNamespace(host_time_ns=0, controller_time=0.0)
    links = SimpleNamespace(rtde=None)  # what watch() reads of the UrLinks: the RTDE link
    diagnosis = Diagnosis(
        links,  # type: ignore[arg-type]
        state,  # type: ignore[arg-type]
        period=0.002,
        headless=True,
        servers=None,  # type: ignore[arg-type]
        program=None,  # type: ignore[arg-type]
    )
    diagnosis.watch()
    assert _reference(diagnosis) is None, "no link, no reference"
    links.rtde = _Link()
    delays = [500, 300, 900, 100, 700, 400, 800, 600, 50, 20]  # µs; the last two come after 8 looks
    for i, delay_us in enumerate(delays):
        state.host_time_ns, state.controller_time = _pair(1000.0 + i * 0.25, delay_us)
        diagnosis.watch()
    assert _reference(diagnosis) == _pair(1000.0 + 3 * 0.25, 100), "the least delayed of the first 8"
    links.rtde = _Link()  # a new link: chosen anew
    state.host_time_ns, state.controller_time = _pair(2000.0, 300)
    diagnosis.watch()
    assert _reference(diagnosis) == _pair(2000.0, 300)


def _reference(diagnosis: Diagnosis) -> tuple[int, float] | None:
    return diagnosis.reference
