"""The Foxglove client test's rule for a missing node: skip and name what is missing, or fail when
``URDAEMON_REQUIRE_NODE=1`` (.ci/run), so a CI machine without node cannot pass by skipping."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.foxglove import node
from tests.foxglove.node import REQUIRE_ENV, node_or_skip


def test_without_node_the_test_skips_naming_the_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv(REQUIRE_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match=r"node \(Debian package: apt-get install nodejs npm\)"):
        node_or_skip()


def test_without_node_it_fails_when_node_is_required(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setenv(REQUIRE_ENV, "1")
    with pytest.raises(pytest.fail.Exception, match=r"node \(Debian package.*URDAEMON_REQUIRE_NODE=1"):
        node_or_skip()


def test_missing_npm_packages_are_named(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: "/usr/bin/node")
    monkeypatch.setattr(node, "HERE", tmp_path)
    monkeypatch.delenv(REQUIRE_ENV, raising=False)
    for package in node.PACKAGES[1:]:
        (tmp_path / "node_modules" / package).mkdir(parents=True)
        (tmp_path / "node_modules" / package / "package.json").write_text("{}", encoding="utf-8")
    with pytest.raises(pytest.skip.Exception, match=r"npm packages @foxglove/ws-protocol \(npm ci --prefix"):
        node_or_skip()
    (tmp_path / "node_modules" / node.PACKAGES[0]).mkdir(parents=True)
    (tmp_path / "node_modules" / node.PACKAGES[0] / "package.json").write_text("{}", encoding="utf-8")
    assert node_or_skip() == "/usr/bin/node"
