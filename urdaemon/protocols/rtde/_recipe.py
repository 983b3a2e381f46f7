"""An RTDE recipe: variable names and their types, compiled once to pack and unpack DATA_PACKAGE values.

Also which type answers a setup reply may carry (a type, or NOT_FOUND / IN_USE) and ``RtdeValue``, the
Python value of one field (§1.5).
"""

from __future__ import annotations

import itertools
import operator
import struct
from bisect import bisect_right
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any, Final, TypeAlias

from urdaemon.protocols.rtde._wire import Buf
from urdaemon.protocols.rtde_variables import (
    BOOL,
    DOUBLE,
    IN_USE,
    INT32,
    NOT_FOUND,
    RTDE_TYPES,
    UINT8,
    UINT32,
    UINT64,
    VECTOR3D,
    VECTOR6D,
    VECTOR6INT32,
    VECTOR6UINT32,
)

__all__ = ["INPUT_ANSWERS", "OUTPUT_ANSWERS", "Recipe", "RtdeValue"]

_STRUCT_CODES: Final[Mapping[str, str]] = MappingProxyType(
    {
        BOOL: "?",
        UINT8: "B",
        UINT32: "I",
        UINT64: "Q",
        INT32: "i",
        DOUBLE: "d",
        VECTOR3D: "3d",
        VECTOR6D: "6d",
        VECTOR6INT32: "6i",
        VECTOR6UINT32: "6I",
    }
)
_VECTOR_LENGTHS: Final[Mapping[str, int]] = MappingProxyType(
    {VECTOR3D: 3, VECTOR6D: 6, VECTOR6INT32: 6, VECTOR6UINT32: 6}
)
OUTPUT_ANSWERS: Final = RTDE_TYPES | {NOT_FOUND}
INPUT_ANSWERS: Final = RTDE_TYPES | {NOT_FOUND, IN_USE}

RtdeValue: TypeAlias = bool | int | float | tuple[float, ...] | tuple[int, ...]
"""One decoded field: a scalar, or a tuple for the VECTOR types."""


class Recipe:
    """RTDE fields compiled once into a ``struct.Struct``: encodes and decodes DATA_PACKAGE bodies."""

    __slots__ = ("_ends", "_lengths", "_regroup", "_struct", "names", "size", "types")

    def __init__(self, names: Sequence[str], types: Sequence[str]) -> None:
        if len(names) != len(types):
            raise ValueError(f"{len(names)} names but {len(types)} types")
        if not types:
            raise ValueError("a recipe needs at least one field")
        for name, rtde_type in zip(names, types, strict=True):
            if rtde_type not in RTDE_TYPES:
                # NOT_FOUND / IN_USE are answers to a setup request: reported, never decoded.
                raise ValueError(f"{name!r} has no RTDE value type: {rtde_type!r}")
        self.names: tuple[str, ...] = tuple(names)
        self.types: tuple[str, ...] = tuple(types)
        self._struct = struct.Struct(">" + "".join(_STRUCT_CODES[t] for t in types))
        self.size: int = self._struct.size
        """Bytes of the packed values (without header or recipe id)."""
        # struct returns vectors as loose items; an itemgetter of one key per field (an index, or a
        # slice for a vector) regroups them in C, ~3x faster than a Python-level map over the keys
        keys: list[int | slice] = []
        at = 0
        for t in types:
            n = _VECTOR_LENGTHS.get(t, 0)
            keys.append(slice(at, at + n) if n else at)
            at += n or 1
        self._regroup: Callable[[tuple[Any, ...]], tuple[RtdeValue, ...]] | None = None
        if at != len(types):
            # itemgetter of one key returns the item itself; a one-field recipe is wrapped again
            getter = operator.itemgetter(*keys)
            self._regroup = getter if len(keys) > 1 else lambda flat: (getter(flat),)
        self._lengths = tuple(_VECTOR_LENGTHS.get(t, 0) for t in types)
        self._ends = tuple(itertools.accumulate(struct.calcsize(">" + _STRUCT_CODES[t]) for t in types))
        """Where each field ends in a packed body (the bytes of it and of the fields before it)."""

    def __repr__(self) -> str:
        return f"Recipe({len(self.names)} fields, {self.size} bytes)"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Recipe) and (self.names, self.types) == (other.names, other.types)

    def __hash__(self) -> int:
        return hash((self.names, self.types))

    def index(self, name: str) -> int:
        """Position of ``name`` in the recipe (and so in every decoded tuple); ValueError if absent."""
        return self.names.index(name)

    def decode(self, payload: Buf, offset: int = 0) -> tuple[RtdeValue, ...]:
        """The values at ``payload[offset:]`` in recipe order; the caller checked ``size`` bytes are there."""
        regroup = self._regroup
        if regroup is None:
            return self._struct.unpack_from(payload, offset)
        return regroup(self._struct.unpack_from(payload, offset))

    def whole_fields(self, size: int) -> int:
        """How many leading fields lie whole in a body of ``size`` bytes (all of them from ``size``)."""
        return bisect_right(self._ends, size)

    def decode_leading(self, payload: Buf, offset: int, size: int) -> tuple[RtdeValue, ...]:
        """The leading fields that lie whole in the ``size`` bytes at ``payload[offset:]``, in recipe
        order: all of them (bytes past the recipe unread) when ``size`` reaches :attr:`size`, fewer
        when the body is shorter (a field cut off, and those after it, left out)."""
        count = self.whole_fields(size)
        if count == len(self.names):
            return self.decode(payload, offset)
        if count == 0:
            return ()
        return Recipe(self.names[:count], self.types[:count]).decode(payload, offset)

    def encode(self, values: Sequence[Any]) -> bytes:
        """``values`` in recipe order packed for the wire; ValueError if they do not fit the types."""
        if len(values) != len(self._lengths):
            raise ValueError(f"recipe has {len(self._lengths)} fields, got {len(values)} values")
        try:
            if self._regroup is None:
                return self._struct.pack(*values)
            flat: list[Any] = []
            for value, n in zip(values, self._lengths, strict=True):
                if n:
                    if len(value) != n:
                        raise ValueError(f"a {n}-vector field got {len(value)} values")
                    flat.extend(value)
                else:
                    flat.append(value)
            return self._struct.pack(*flat)
        except (struct.error, TypeError) as err:
            raise ValueError(f"values do not fit the recipe types: {err}") from err
