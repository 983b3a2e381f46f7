"""Goal messages a client can trust: each accepted goal gets a key only its client learns (in the
reply that accepts it), and every feedback and result message of the goal carries, as its Zenoh
attachment, an HMAC-SHA256 under that key of the Zenoh key the message is published on and its
payload. Another session can publish on a goal's keys, but cannot sign, and cannot move a signed
message to another key (a feedback re-published on the result key no longer verifies); the client
drops what does not verify (docs/security.md).

The signed bytes are ``key_expr.encode() + b"\\0" + payload`` (a key expression never holds a NUL,
so no two (key, payload) pairs sign the same bytes); the signature is the HMAC's lowercase hex, as
ASCII bytes.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets

__all__ = ["KEY_BYTES", "is_key", "new_key", "sign", "verify"]

KEY_BYTES = 32
"""Length of a goal's key (hex in the accepting reply: twice as many characters)."""

_KEY = re.compile(f"[0-9a-f]{{{2 * KEY_BYTES}}}")


def new_key() -> str:
    """A fresh goal key, as lowercase hex."""
    return secrets.token_hex(KEY_BYTES)


def is_key(key: object) -> bool:
    """Whether ``key`` is a goal key as the daemon gives them: ``2 * KEY_BYTES`` lowercase hex chars."""
    return isinstance(key, str) and _KEY.fullmatch(key) is not None


def sign(key: str, key_expr: str, payload: bytes) -> bytes:
    """The attachment of ``payload`` published on ``key_expr``: HMAC-SHA256 under ``key`` (hex) of
    ``key_expr.encode() + b"\\0" + payload``, as ASCII hex. Raises ``ValueError`` if ``key`` is not
    hex."""
    mac = hmac.new(bytes.fromhex(key), key_expr.encode(), hashlib.sha256)
    mac.update(b"\0")
    mac.update(payload)
    return mac.hexdigest().encode()


def verify(key: str, key_expr: str, payload: bytes, attachment: bytes | None) -> bool:
    """Whether ``attachment`` is the signature of ``payload`` on ``key_expr`` under ``key`` (compared
    in constant time). False for a key that is not a goal key (``is_key``: never an empty key)."""
    if attachment is None or not is_key(key):
        return False
    return hmac.compare_digest(sign(key, key_expr, payload), attachment)
