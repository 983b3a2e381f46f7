"""The suite leaves to the machine what the machine decides (issue 32: red under load, green alone)."""

from __future__ import annotations

import re
from pathlib import Path

from hypothesis import HealthCheck, settings

TESTS = Path(__file__).resolve().parent


def test_hypothesis_has_no_deadline_and_no_too_slow_check() -> None:
    """Reproduction: the dashboard fuzzers failed on hypothesis's 200 ms deadline under load."""
    default = settings.default
    assert default is not None
    assert default.deadline is None
    assert HealthCheck.too_slow in default.suppress_health_check
    assert settings(max_examples=5).deadline is None  # a test's own settings inherit it


def test_no_test_sets_a_deadline_of_its_own() -> None:
    offenders = [
        f"{path.relative_to(TESTS)}:{n}"
        for path in sorted(TESTS.rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if re.search(r"\bdeadline=(?!None)", line)
    ]
    assert offenders == []
