"""The `ur` backend: drive a real UR controller over its own protocols."""

from __future__ import annotations
