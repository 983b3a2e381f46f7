"""Why a client's TLS session to the daemon did not come up, in words a user can act on.

Zenoh opens a peer session even when its TLS handshake fails, and says nothing about why, so the
client checks what it can itself: before connecting, the files its Zenoh config names (the root CA,
its certificate and private key: there, PEM, and the key the certificate's) (``tls_file_problem``);
and when no session came up, one TLS handshake of its own with the same files to the same endpoint
(``tls_handshake_problem``), whose failure names the cause: nothing listening, the daemon's
certificate not signed by the client's CA, the daemon's certificate not for the name dialled, or the
daemon refusing the client's certificate (none given, or not signed by the CA it trusts).
"""

from __future__ import annotations

import contextlib
import json
import socket
import ssl
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["TlsFiles", "tls_file_problem", "tls_files", "tls_handshake_problem"]


@dataclass(frozen=True, slots=True)
class TlsFiles:
    """The TLS files a client's Zenoh config names."""

    root_ca: str | None
    certificate: str | None
    private_key: str | None


def tls_files(conf: Any) -> TlsFiles:
    """The files ``conf`` (a ``zenoh.Config``) names under ``transport/link/tls``."""

    def get(name: str) -> str | None:
        try:
            value = json.loads(conf.get_json(f"transport/link/tls/{name}"))
        except Exception:  # a key this Zenoh does not know, or not set
            return None
        return value if isinstance(value, str) and value else None

    return TlsFiles(get("root_ca_certificate"), get("connect_certificate"), get("connect_private_key"))


def _context(files: TlsFiles) -> ssl.SSLContext:
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    if files.root_ca is not None:
        context.load_verify_locations(files.root_ca)
    if files.certificate is not None and files.private_key is not None:
        context.load_cert_chain(files.certificate, files.private_key)
    return context


def tls_file_problem(files: TlsFiles, config_file: str | None) -> str | None:
    """What is wrong with the TLS files (None: each is there, PEM, and the key is the certificate's)."""
    where = f" (named in {config_file})" if config_file else ""
    for what, path in (
        ("root CA certificate", files.root_ca),
        ("client certificate", files.certificate),
        ("client private key", files.private_key),
    ):
        if path is not None and not Path(path).is_file():
            return f"the {what} file {path}{where} does not exist"
    if (files.certificate is None) != (files.private_key is None):
        return f"a client certificate needs its private key and the key its certificate{where}"
    if files.root_ca is not None:
        try:
            ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT).load_verify_locations(files.root_ca)
        except (ssl.SSLError, ValueError) as err:
            return f"the root CA certificate {files.root_ca}{where} is not a PEM certificate ({_said(err)})"
    if files.certificate is not None and files.private_key is not None:
        try:
            ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT).load_cert_chain(files.certificate, files.private_key)
        except (ssl.SSLError, ValueError) as err:
            return (
                f"the client certificate {files.certificate} and private key {files.private_key}{where} "
                f"do not load together: not PEM, or the key is not the certificate's ({_said(err)})"
            )
    return None


def tls_handshake_problem(endpoint: str, files: TlsFiles, timeout: float) -> str:
    """Why a TLS session to ``endpoint`` (``tls/HOST:PORT``) does not come up, from one handshake
    made here with ``files``: blocking, up to ``timeout`` s for each step."""
    host, _, port = endpoint.split("/", 1)[1].rpartition(":")
    host = host.strip("[]")
    try:
        raw = socket.create_connection((host, int(port)), timeout=timeout)
    except (OSError, ValueError) as err:
        return f"nothing accepts a connection at {host}:{port} ({_said(err)}): is the daemon running there?"
    with contextlib.closing(raw):
        try:
            tls = _context(files).wrap_socket(raw, server_hostname=host)
        except ssl.SSLCertVerificationError as err:
            return _verify_problem(err, host, files)
        except ssl.SSLError as err:
            return _refused(err, files)
        except OSError as err:
            return f"the TLS handshake with {host}:{port} failed: {_said(err)}"
        with contextlib.closing(tls):
            tls.settimeout(min(timeout, 1.0))
            try:  # TLS 1.3: a client certificate the daemon refuses is told after the handshake
                tls.recv(1)
            except ssl.SSLError as err:
                return _refused(err, files)
            except OSError:
                pass
    return (
        f"the TLS handshake with {host}:{port} succeeds from here, but no Zenoh session came up: "
        "is it a urdaemon (Zenoh) endpoint, and does the daemon's access control let this client in?"
    )


def _verify_problem(err: ssl.SSLCertVerificationError, host: str, files: TlsFiles) -> str:
    message = str(err.verify_message or err.reason or err)
    if "hostname" in message.lower() or "ip address mismatch" in message.lower():
        return (
            f"TLS: the daemon's certificate is not for {host!r} (name mismatch: {message}); dial the "
            "name or address its certificate names (urdaemon client-config --endpoint)"
        )
    return (
        f"TLS: the daemon's certificate is not signed by the root CA {files.root_ca} ({message}): the "
        "client's root_ca_certificate must be the CA that signed the daemon's certificate"
    )


def _refused(err: ssl.SSLError, files: TlsFiles) -> str:
    reason = str(err.reason or err).lower().replace("_", " ")
    if "certificate required" in reason or (files.certificate is None and "handshake" in reason):
        return (
            "TLS: the daemon asks for a client certificate (mutual TLS) and this client gave none: "
            "write a config with urdaemon client-config --certificate … --private-key …"
        )
    if "unknown ca" in reason or "bad certificate" in reason or "certificate" in reason:
        return (
            f"TLS: the daemon refused this client's certificate {files.certificate} ({_said(err)}): it "
            "must be signed by the CA the daemon trusts (the cell file's zenoh.tls.root_ca)"
        )
    return f"TLS: the handshake failed: {_said(err)}"


def _said(err: BaseException) -> str:
    if isinstance(err, ssl.SSLError) and err.reason:
        return str(err.reason).replace("_", " ").lower()
    return str(err) or type(err).__name__
