"""Zenoh transport security from the cell file: TLS, mutual TLS and access control (docs/security.md).

``configure_daemon`` adds what the cell file's ``zenoh`` section asks for to the daemon's session
config (publish/node.py ``serve_config``); nothing when the cell file asks for none.
"""

from __future__ import annotations

from typing import Any

from urdaemon.cell.config import ZenohOptions

__all__ = ["configure_daemon"]


def configure_daemon(conf: Any, options: ZenohOptions) -> None:
    """Add the cell file's TLS and access control settings to the daemon's ``zenoh.Config``."""
    del conf, options  # the cell file has no transport security settings yet (issue 16)
