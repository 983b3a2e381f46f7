"""The cell file: schema and loader."""

from __future__ import annotations

from urdaemon.cell.config import Cell, Robot, ur_models
from urdaemon.cell.load import load_cell, parse_cell, summarize

__all__ = ["Cell", "Robot", "load_cell", "parse_cell", "summarize", "ur_models"]
