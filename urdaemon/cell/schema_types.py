"""What every part of the cell-file schema is built from: a frozen, strict model that refuses unknown
keys and loose types, a float that must be finite, the slowest control cycle, the pattern of a host
name, and a file named relative to the cell file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, model_validator

__all__ = ["HOST_NAME_PATTERN", "MIN_CYCLE_RATE_HZ", "Finite", "Frozen", "resolve_file", "resolve_path"]

Finite = Annotated[float, Field(allow_inf_nan=False)]
"""A float that is neither infinite nor NaN."""


class Frozen(BaseModel):
    """A cell-file section: immutable once loaded; an unknown key is an error, and so is a loose type.

    Strict: a number is a YAML number (``"50"`` is text, ``true`` is no integer), a whole number is
    no float, a flag is ``true``/``false``; an integer where a float is expected stays fine. YAML
    gives sequences as lists, which the tuple fields take as they are.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    @model_validator(mode="before")
    @classmethod
    def _sequences_as_tuples(cls, data: Any) -> Any:
        # Strict tuples take only tuples; a YAML (or JSON) sequence is a list. Items stay strict.
        if not isinstance(data, dict):
            return data
        return {key: tuple(v) if isinstance(v, list) else v for key, v in data.items()}


MIN_CYCLE_RATE_HZ = 10.0
"""Slowest control cycle a mock or servo arm may run: ten periods within a second, two within the
default 0.2 s stream deadman. (A UR runs at its controller's 500 or 125 Hz.)"""

HOST_NAME_PATTERN = r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*\.?$"
"""A DNS host name (labels of letters, digits and hyphens), as a robot's address or a router's host."""


def resolve_path(value: str, info: ValidationInfo) -> Path:
    """The path ``value`` names (``~`` expanded), relative to the cell file's folder (validation
    context ``base_dir``); whether it exists is the caller's check."""
    base = (info.context or {}).get("base_dir")
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    return path


def resolve_file(value: str, info: ValidationInfo) -> str:
    """The absolute path of the file ``value`` names, relative to the cell file's folder (validation
    context ``base_dir``); ValueError if there is no such file."""
    path = resolve_path(value, info)
    if not path.is_file():
        raise ValueError(f"file not found: {path}")
    return str(path.resolve())
