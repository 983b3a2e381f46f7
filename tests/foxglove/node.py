"""Node and the npm packages of tests/foxglove/ (package.json, package-lock.json) for the independent
Foxglove client: found, or the test skips naming what is missing, unless ``URDAEMON_REQUIRE_NODE=1``
(set by .ci/run, which installs both), where a missing one is a failure."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

__all__ = ["CLIENT", "HERE", "PACKAGES", "REQUIRE_ENV", "node_or_skip"]

HERE = Path(__file__).resolve().parent
CLIENT = HERE / "client.mjs"
REQUIRE_ENV = "URDAEMON_REQUIRE_NODE"
"""Set to 1: missing node or npm packages fail the test instead of skipping it."""
PACKAGES = ("@foxglove/ws-protocol", "@foxglove/rosmsg", "@foxglove/rosmsg2-serialization", "ws")


def node_or_skip() -> str:
    """The path of node; skip (or fail under ``URDAEMON_REQUIRE_NODE=1``), naming what is missing."""
    missing = []
    path = shutil.which("node")
    if path is None:
        missing.append("node (Debian package: apt-get install nodejs npm)")
    absent = [p for p in PACKAGES if not (HERE / "node_modules" / p / "package.json").is_file()]
    if absent:
        missing.append(f"the npm packages {', '.join(absent)} (npm ci --prefix tests/foxglove)")
    if missing:
        reason = "the Foxglove client test needs " + " and ".join(missing)
        if os.environ.get(REQUIRE_ENV) == "1":
            pytest.fail(f"{reason} ({REQUIRE_ENV}=1)", pytrace=False)
        pytest.skip(reason)
    assert path is not None
    return path
