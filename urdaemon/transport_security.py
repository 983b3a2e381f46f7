"""A client's Zenoh config for a TLS cell (docs/security.md): ``client_config`` and
``write_client_config`` make the config a client connects with, ``urdaemon client-config`` writes it.

The daemon's own side (its TLS settings and the access rules its session enforces) is the session's:
publish/session_config.py and publish/access.py.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from urdaemon.cell.config import Cell
from urdaemon.cell.zenoh_options import SECURE_PROTOCOLS
from urdaemon.errors import ConfigError

__all__ = [
    "add_client_config_arguments",
    "client_config",
    "client_config_command",
    "client_config_main",
    "write_client_config",
]


def client_config(
    cell: Cell, *, certificate: str | None, private_key: str | None, endpoint: str | None = None
) -> dict[str, Any]:
    """A client's Zenoh config for ``cell``'s daemon: client mode on the daemon's ``tls/`` endpoint,
    the cell's root CA, and (mutual TLS) the client's certificate and key. Paths become absolute."""
    tls = cell.zenoh.tls
    if tls is None:
        raise ConfigError(f"cell {cell.cell!r}: zenoh.tls is not set: the daemon does not use TLS")
    if tls.mutual and (certificate is None or private_key is None):
        raise ConfigError("the daemon asks for mutual TLS: give the client's certificate and private key")
    endpoint = endpoint or _dialable(cell)
    if not endpoint.startswith(SECURE_PROTOCOLS):
        raise ConfigError(f"endpoint {endpoint}: a TLS client needs a tls/ or quic/ endpoint")
    link: dict[str, Any] = {"root_ca_certificate": _existing(tls.root_ca, "root CA")}
    if certificate is not None and private_key is not None:
        link["connect_certificate"] = _existing(certificate, "certificate")
        link["connect_private_key"] = _existing(private_key, "private key")
        link["enable_mtls"] = True
    return {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": link}},
    }


def _dialable(cell: Cell) -> str:
    """The daemon's first secure listen endpoint, if a client can dial its address as written."""
    for endpoint in cell.zenoh.listen:
        if endpoint.startswith(SECURE_PROTOCOLS):
            host = endpoint.split("/", 1)[1].rsplit(":", 1)[0].strip("[]")
            if host in ("0.0.0.0", "::"):
                raise ConfigError(
                    f"zenoh.listen: {endpoint} listens on every interface; give the endpoint clients "
                    "dial (--endpoint tls/HOST:PORT, HOST as in the daemon's certificate)"
                )
            return endpoint
    raise ConfigError("zenoh.listen has no tls/ endpoint; give the one clients dial (--endpoint)")


def _existing(path: str, what: str) -> str:
    resolved = Path(path).expanduser().resolve()
    if not resolved.is_file():
        raise ConfigError(f"{what} file not found: {resolved}")
    return str(resolved)


def write_client_config(
    cell: Cell,
    *,
    certificate: str | None,
    private_key: str | None,
    path: str | Path,
    endpoint: str | None = None,
) -> Path:
    """Write :func:`client_config` to ``path`` as JSON5 (plain JSON) readable by its owner only: it
    names the client's private key. Returns the path."""
    text = json.dumps(
        client_config(cell, certificate=certificate, private_key=private_key, endpoint=endpoint), indent=2
    )
    path = Path(path)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        out.write(text + "\n")
    return path


def add_client_config_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``urdaemon client-config``."""
    parser.add_argument("--config", required=True, help="the daemon's cell file (YAML)")
    parser.add_argument("--certificate", default=None, help="the client's certificate (PEM), for mTLS")
    parser.add_argument("--private-key", default=None, help="the client's private key (PEM), for mTLS")
    parser.add_argument(
        "--endpoint", default=None, help="the daemon's endpoint as clients dial it (default: its tls/ listen)"
    )
    parser.add_argument("--output", required=True, help="Zenoh config file to write (JSON5)")


def client_config_command(args: argparse.Namespace) -> int:
    """Run ``urdaemon client-config`` with parsed arguments; 0 on success, 2 on bad input."""
    from urdaemon.cell import load_cell

    try:
        cell = load_cell(args.config)
        path = write_client_config(
            cell,
            certificate=args.certificate,
            private_key=args.private_key,
            path=args.output,
            endpoint=args.endpoint,
        )
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"error: cannot write {args.output}: {err.strerror or err}", file=sys.stderr)
        return 2
    print(f"wrote {path}: connect with --zenoh-config {path} (Client.connect(config_file=...))")
    return 0


def client_config_main(argv: Sequence[str] | None = None) -> int:
    """``urdaemon client-config`` as a function of its arguments (without the command name)."""
    parser = argparse.ArgumentParser(
        prog="urdaemon client-config", description="write a client's Zenoh config for a TLS cell"
    )
    add_client_config_arguments(parser)
    return client_config_command(parser.parse_args(sys.argv[1:] if argv is None else list(argv)))
