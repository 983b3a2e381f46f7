"""The cell file: schema and loader."""

from __future__ import annotations

from urdaemon.cell.config import Cell
from urdaemon.cell.load import load_cell, parse_cell, summarize
from urdaemon.cell.robot_options import Robot, ur_models

__all__ = ["Cell", "Robot", "load_cell", "parse_cell", "summarize", "ur_models"]
