"""The suite's settings that the machine, not the code, decides, and what keeps collection light.

Hypothesis: no per-example deadline (its default 200 ms failed the dashboard fuzzers on a loaded
2-core machine, issue 32) and no "too slow" health check: on a busy machine examples are slow
because the CPU is shared, which says nothing about the code. Every example still runs, and every
test keeps pytest-timeout's bound (pyproject.toml). Imports nothing of urdaemon: collection stays
light (``python -X importtime -m pytest --collect-only``).

Compiled code is cached under ``.pytest_cache/pycache`` even where ``PYTHONDONTWRITEBYTECODE`` is set
(this project's Dockerfile, many CI images): without a cache, pytest rewrote the asserts of every
test module and Python compiled every module of urdaemon again at each collection, in each xdist
worker and in each ``urdaemon`` subprocess a test starts (8 s of CPU per collection here; 124 s of
wall time on a loaded 2-core machine with four workers). Nothing is written next to the sources.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings

if sys.dont_write_bytecode or os.environ.get("PYTHONDONTWRITEBYTECODE"):
    _prefix = str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "pycache")
    sys.pycache_prefix = _prefix  # this process: the test modules pytest rewrites, the imports after this
    sys.dont_write_bytecode = False
    os.environ["PYTHONPYCACHEPREFIX"] = _prefix  # the processes tests start: urdaemon, fakes
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

settings.register_profile("machine-decides", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("machine-decides")
