"""Where the shipped resources live: inside an installed wheel, or beside the package in a checkout."""

from __future__ import annotations

from functools import cache
from pathlib import Path

__all__ = ["resource_path", "resources_dir"]


@cache
def resources_dir() -> Path:
    """The resources folder: ``urdaemon/resources`` in a wheel, ``<checkout>/resources`` otherwise."""
    package = Path(__file__).resolve().parent
    for candidate in (package / "resources", package.parent / "resources"):
        if (candidate / "ur").is_dir():
            return candidate
    raise FileNotFoundError(f"urdaemon resources not found beside {package}")


def resource_path(*parts: str) -> Path:
    """A path inside the resources folder."""
    return resources_dir().joinpath(*parts)
