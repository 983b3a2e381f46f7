"""The argument types every ``urdaemon`` command shares: whole numbers, seconds, rates, ports. Each
refuses with argparse's error naming what it wanted and what it got."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["port", "rate_hz", "seconds", "whole_number"]


def whole_number(minimum: int) -> Callable[[str], int]:
    """A whole number ``>= minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {minimum}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {minimum}, got {value}")
        return value

    return parse


def seconds(allow_zero: bool) -> Callable[[str], float]:
    """A finite number of seconds, > 0 (or >= 0 with ``allow_zero``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            bound = ">= 0" if allow_zero else "> 0"
            raise argparse.ArgumentTypeError(f"must be a finite number of seconds {bound}, got {text}")
        return value

    return parse


def rate_hz(text: str) -> float:
    """A finite rate > 0 (Hz)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a rate in Hz, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite rate in Hz > 0, got {text}")
    return value


def port(allow_zero: bool) -> Callable[[str], int]:
    """A TCP port, 1..65535 (0..65535 with ``allow_zero``: any free port)."""
    low = 0 if allow_zero else 1

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a port number, got {text!r}") from None
        if not low <= value < 65536:
            raise argparse.ArgumentTypeError(f"must be within {low}..65535, got {value}")
        return value

    return parse
