"""Goal messages a client can trust: each accepted goal gets a key only its client learns (in the
reply that accepts it), and every feedback and result message of the goal carries, as its Zenoh
attachment, an HMAC-SHA256 of its payload under that key. Another session can publish on a goal's
keys, but cannot sign; the client drops what does not verify (docs/security.md)."""

from __future__ import annotations

import hashlib
import hmac
import secrets

__all__ = ["KEY_BYTES", "new_key", "sign", "verify"]

KEY_BYTES = 32
"""Length of a goal's key (hex in the accepting reply: twice as many characters)."""


def new_key() -> str:
    """A fresh goal key, as hex."""
    return secrets.token_hex(KEY_BYTES)


def sign(key: str, payload: bytes) -> bytes:
    """The attachment that goes with ``payload``: its HMAC-SHA256 under ``key``, as ASCII hex."""
    return hmac.new(bytes.fromhex(key), payload, hashlib.sha256).hexdigest().encode()


def verify(key: str, payload: bytes, attachment: bytes | None) -> bool:
    """Whether ``attachment`` is ``payload``'s signature under ``key`` (compared in constant time)."""
    return attachment is not None and hmac.compare_digest(sign(key, payload), attachment)
