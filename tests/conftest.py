"""The suite's settings that the machine, not the code, decides.

Hypothesis: no per-example deadline (its default 200 ms failed the dashboard fuzzers on a loaded
2-core machine, issue 32) and no "too slow" health check: on a busy machine examples are slow
because the CPU is shared, which says nothing about the code. Every example still runs, and every
test keeps pytest-timeout's bound (pyproject.toml). Imports nothing of urdaemon: collection stays
light (``python -X importtime -m pytest --collect-only``).
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

settings.register_profile("machine-decides", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("machine-decides")
