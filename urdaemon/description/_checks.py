"""Small validators for the YAML files of this package; each failure names the offending key."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["BadKey", "as_float", "floats", "mapping", "only_keys", "vec3"]


class BadKey(Exception):
    """One key of a data file is wrong; ``key`` is its dotted path, ``reason`` says why."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"{key}: {reason}")
        self.key = key
        self.reason = reason


def mapping(value: Any, key: str) -> dict[str, Any]:
    """``value`` if it is a mapping."""
    if not isinstance(value, dict):
        raise BadKey(key, f"must be a mapping, got {type(value).__name__}")
    return value


def only_keys(
    value: dict[str, Any], key: str, required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> None:
    """Fail on the first missing required key or the first key that is neither required nor optional."""
    where = f"{key}." if key else ""
    for name in required:
        if name not in value:
            raise BadKey(f"{where}{name}", "required key is missing")
    unknown = sorted(str(k) for k in value if k not in required and k not in optional)
    if unknown:
        raise BadKey(f"{where}{unknown[0]}", "unknown key")


def as_float(value: Any, key: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    """``value`` as a finite float (ints accepted, bools not)."""
    # bool is an int subclass; `true` where a number belongs is a typo, not 1.0
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadKey(key, f"must be a number, got {value!r}")
    result = float(value)
    if not math.isfinite(result):
        raise BadKey(key, f"must be finite, got {result}")
    if positive and result <= 0.0:
        raise BadKey(key, f"must be positive, got {result}")
    if nonnegative and result < 0.0:
        raise BadKey(key, f"must not be negative, got {result}")
    return result


def floats(value: Any, count: int, key: str) -> tuple[float, ...]:
    """``value`` as a tuple of exactly ``count`` finite floats."""
    if not isinstance(value, list | tuple):
        raise BadKey(key, f"must be a list of {count} numbers, got {type(value).__name__}")
    if len(value) != count:
        raise BadKey(key, f"must have {count} values, got {len(value)}")
    return tuple(as_float(v, f"{key}[{i}]") for i, v in enumerate(value))


def vec3(value: Any, key: str) -> tuple[float, float, float]:
    """``value`` as three finite floats."""
    x, y, z = floats(value, 3, key)
    return (x, y, z)
