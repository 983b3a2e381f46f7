"""What every part of the cell-file schema is built from: a frozen model that refuses unknown keys,
a float that must be finite, the pattern of a host name, and a file named relative to the cell file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo

__all__ = ["HOST_NAME_PATTERN", "Finite", "Frozen", "resolve_file"]

Finite = Annotated[float, Field(allow_inf_nan=False)]
"""A float that is neither infinite nor NaN."""


class Frozen(BaseModel):
    """A cell-file section: immutable once loaded, and an unknown key is an error."""

    model_config = ConfigDict(frozen=True, extra="forbid")


HOST_NAME_PATTERN = r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*\.?$"
"""A DNS host name (labels of letters, digits and hyphens), as a robot's address or a router's host."""


def resolve_file(value: str, info: ValidationInfo) -> str:
    """The absolute path of the file ``value`` names, relative to the cell file's folder (validation
    context ``base_dir``); ValueError if there is no such file."""
    base = (info.context or {}).get("base_dir")
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    if not path.is_file():
        raise ValueError(f"file not found: {path}")
    return str(path.resolve())
