"""The kinematics hash UR's client library compares against a description's ``kinematics.hash``.

docs/protocols.md §2.6: a text string is built from the DH parameters reported in KINEMATICS_INFO
(§2.2), joint by joint in the order theta, d, a, alpha (not the wire order), every number printed
the way a default C++ ``ostream`` prints a ``double`` (printf ``%g``, 6 significant digits), and
hashed with libstdc++'s 64-bit ``std::hash<std::string>`` (``_Hash_bytes``, a MurmurHash64A
variant). The result is ``calib_<unsigned decimal>``.

The value is only meaningful as an equality check against the hashes shipped with UR's robot
descriptions: it depends on libstdc++, so a build against another C++ library prints other values.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Final

from urdaemon.model import UR_JOINT_COUNT

__all__ = [
    "DH_JOINT_COUNT",
    "KINEMATICS_HASH_PATTERN",
    "KINEMATICS_HASH_PREFIX",
    "kinematics_hash",
    "kinematics_hash_text",
    "libstdcxx_hash_bytes",
]

DH_JOINT_COUNT: Final = UR_JOINT_COUNT
"""Joints per DH parameter list (every UR arm has six); §2.2 KINEMATICS_INFO."""

KINEMATICS_HASH_PREFIX: Final = "calib_"
"""Prefix of the printed hash; §2.6 step 4."""
KINEMATICS_HASH_PATTERN: Final = re.compile(rf"^{KINEMATICS_HASH_PREFIX}[0-9]+$")
"""A whole printed hash, ``calib_<unsigned decimal>`` (what calibration files and model data hold)."""

_MASK64: Final = (1 << 64) - 1
# libstdc++ libsupc++/hash_bytes.cc, 64-bit branch; constants as listed in §2.6 step 3
_MUL: Final = 0xC6A4A7935BD1E995
_SEED: Final = 0xC70F6907


def _shift_mix(v: int) -> int:
    return v ^ (v >> 47)


def libstdcxx_hash_bytes(data: bytes, seed: int = _SEED) -> int:
    """libstdc++'s 64-bit ``_Hash_bytes(data, len, seed)`` (what ``std::hash<std::string>`` returns); §2.6."""
    length = len(data)
    h = (seed ^ (length * _MUL)) & _MASK64
    full = length - length % 8
    for start in range(0, full, 8):
        # libstdc++ loads each block in host order; the published hashes come from little-endian hosts
        w = int.from_bytes(data[start : start + 8], "little")
        w = (_shift_mix((w * _MUL) & _MASK64) * _MUL) & _MASK64
        h = ((h ^ w) * _MUL) & _MASK64
    if full != length:
        tail = int.from_bytes(data[full:], "little")
        h = ((h ^ tail) * _MUL) & _MASK64
    h = (_shift_mix(h) * _MUL) & _MASK64
    return _shift_mix(h)


def _ostream_double(x: float) -> str:
    # a default std::ostream prints doubles like printf("%g") with precision 6, keeping the sign of
    # -0.0 ("-0"); Python's "g" presentation follows the same C rules
    return f"{x:.6g}"


def kinematics_hash_text(
    theta: Sequence[float], a: Sequence[float], d: Sequence[float], alpha: Sequence[float]
) -> str:
    """The string §2.6 hashes: per joint theta, d, a, alpha, each ``%.6g``, no separators."""
    for name, values in (("theta", theta), ("a", a), ("d", d), ("alpha", alpha)):
        if len(values) != DH_JOINT_COUNT:
            raise ValueError(f"kinematics hash: {name} has {len(values)} values, expected {DH_JOINT_COUNT}")
    return "".join(
        _ostream_double(theta[i]) + _ostream_double(d[i]) + _ostream_double(a[i]) + _ostream_double(alpha[i])
        for i in range(DH_JOINT_COUNT)
    )


def kinematics_hash(
    theta: Sequence[float], a: Sequence[float], d: Sequence[float], alpha: Sequence[float]
) -> str:
    """``calib_<digits>`` for these DH parameters, equal to urcl's ``KinematicsInfo::toHash``; §2.6."""
    text = kinematics_hash_text(theta, a, d, alpha)
    return f"{KINEMATICS_HASH_PREFIX}{libstdcxx_hash_bytes(text.encode('ascii'))}"
