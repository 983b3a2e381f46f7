"""The browser tests' rule for a missing browser: skip and name what is missing, or fail when
``URDAEMON_REQUIRE_BROWSER=1`` (CI), so a CI machine without chromium cannot pass by skipping.

Reproduction: before issue 18 there were no browser tests (tests/browser/ did not exist).
"""

from __future__ import annotations

import shutil

import pytest

from tests.browser.chromium import REQUIRE_ENV, chromium_or_skip


def test_without_chromium_the_tests_skip_naming_the_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv(REQUIRE_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match=r"chromium \(Debian package"):
        chromium_or_skip()


def test_without_chromium_they_fail_when_a_browser_is_required(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setenv(REQUIRE_ENV, "1")
    with pytest.raises(pytest.fail.Exception, match=r"chromium \(Debian package.*URDAEMON_REQUIRE_BROWSER=1"):
        chromium_or_skip()
