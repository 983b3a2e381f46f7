"""What every part of the cell-file schema is built from: a frozen model that refuses unknown keys,
and a float that must be finite."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["Finite", "Frozen"]

Finite = Annotated[float, Field(allow_inf_nan=False)]
"""A float that is neither infinite nor NaN."""


class Frozen(BaseModel):
    """A cell-file section: immutable once loaded, and an unknown key is an error."""

    model_config = ConfigDict(frozen=True, extra="forbid")
