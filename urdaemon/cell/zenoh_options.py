"""The cell file's ``zenoh`` section: how the daemon joins the Zenoh network, its TLS and its access
control (docs/security.md, docs/scale-out.md)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from urdaemon.cell.schema_types import Frozen, resolve_file

__all__ = [
    "ALL_ROBOTS",
    "DEFAULT_ENDPOINT",
    "ENDPOINT_PATTERN",
    "IDENTITY_PATTERN",
    "SECURE_PROTOCOLS",
    "AccessOptions",
    "Grant",
    "Identity",
    "TlsOptions",
    "ZenohOptions",
    "endpoint_port",
]

ENDPOINT_PATTERN = r"^(tcp|udp|tls|quic|ws|unixsock-stream|serial)/\S+$"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
"""Where the daemon listens for Zenoh sessions by default, and where clients look for it."""


def endpoint_port(endpoint: str) -> int | None:
    """The TCP port of a Zenoh ``tcp/HOST:PORT`` endpoint (None for other protocols)."""
    match = re.match(r"^tcp/.*:(\d{1,5})(#.*)?$", endpoint)
    return int(match.group(1)) if match else None


IDENTITY_PATTERN = r"^[A-Za-z][A-Za-z0-9_-]{0,31}$"
"""Names of access-control identities in the cell file (``operator``, ``line-pc``)."""
ALL_ROBOTS = "*"
"""In a grant's ``read`` or ``command`` list: every robot of the cell, and the cell's own keys."""
SECURE_PROTOCOLS = ("tls/", "quic/")
"""Endpoints whose links are encrypted and carry the peer's certificate."""


_PEM_CERTIFICATE = "-----BEGIN CERTIFICATE-----"
_PEM_KEY = "-----BEGIN (RSA |EC )?PRIVATE KEY-----"
"""What Zenoh reads: PEM certificates, and unencrypted PKCS#8, RSA or EC private keys."""


class TlsOptions(Frozen):
    """TLS for the daemon's Zenoh links (``tls/`` and ``quic/`` endpoints); docs/security.md."""

    root_ca: str
    """The certificate authority (PEM) that signed the daemon's and the clients' certificates."""
    certificate: str
    """The daemon's certificate (PEM): its name or IP address in subjectAltName, as clients dial it."""
    private_key: str
    """The daemon's private key (PEM); keep it readable by the daemon's user only."""
    mutual: bool = True
    """Mutual TLS: a client must show a certificate the root CA signed, or its link is refused; the
    certificate's common name is the client's identity for ``access``. ``false``: encryption only,
    anyone who reaches the port may connect."""

    @field_validator("root_ca", "certificate", "private_key")
    @classmethod
    def _exists(cls, value: str, info: ValidationInfo) -> str:
        try:
            path = resolve_file(value, info)
        except ValueError as err:
            raise ValueError(f"{err} (docs/security.md shows how to make the certificates)") from None
        try:
            text = Path(path).read_text(encoding="ascii", errors="replace")
        except OSError as err:
            raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
        want = _PEM_KEY if info.field_name == "private_key" else _PEM_CERTIFICATE
        if not re.search(want, text):
            raise ValueError(f"{path} holds no {want.replace('(RSA |EC )?', '')} in PEM form")
        return path


class Identity(Frozen):
    """Who a connection is, for ``access``: each list given must match (common name AND interface)."""

    cert_common_names: tuple[Annotated[str, Field(min_length=1, max_length=64)], ...] | None = None
    """The common name (CN) of the client certificate the link was opened with (needs mutual TLS)."""
    interfaces: tuple[Annotated[str, Field(pattern=r"^[A-Za-z0-9_.:@-]{1,15}$")], ...] | None = None
    """The daemon's network interface the link arrived on (``lo``, ``eth1``)."""

    @model_validator(mode="after")
    def _says_who(self) -> Identity:
        for field in ("cert_common_names", "interfaces"):
            if getattr(self, field) == ():
                raise ValueError(f"{field}: an empty list matches nobody; leave the field out instead")
        if self.cert_common_names is None and self.interfaces is None:
            raise ValueError(
                "an identity needs cert_common_names or interfaces (one without either would match "
                "every connection)"
            )
        return self


RobotRef = Annotated[str, Field(pattern=rf"^(\{ALL_ROBOTS}|[a-z][a-z0-9_]{{0,30}})$")]


class Grant(Frozen):
    """What some identities may do: read robots' state, command robots."""

    identities: tuple[Annotated[str, Field(pattern=IDENTITY_PATTERN)], ...]
    read: tuple[RobotRef, ...] = ()
    """Robots whose state these identities may subscribe to and ask for (joint states, status, io,
    events, goal feedback and results, cycle stats, the cell's description); ``"*"``: every robot,
    the cell's tf and the cell goals' messages."""
    command: tuple[RobotRef, ...] = ()
    """Robots these identities may command (goals, cancel, services, command streams, the command
    lease and its liveliness token), and read as above; ``"*"``: every robot and cell goals."""

    @model_validator(mode="after")
    def _grants_something(self) -> Grant:
        if not self.identities:
            raise ValueError("identities: list at least one identity the grant is for")
        if not self.read and not self.command:
            raise ValueError("a grant needs 'read' or 'command' (robot names, or '*' for all)")
        return self


class AccessOptions(Frozen):
    """Zenoh access control on the daemon's links: only what a grant allows passes (docs/security.md).

    ``stop`` (every robot's and the cell's) and finding the cell's robots are allowed to every
    connection that reaches the daemon, whatever the grants say: a stop is never refused.
    """

    default: Literal["deny"] = "deny"
    """What no grant allows is dropped by the daemon's Zenoh session (the only choice: said here so
    the cell file reads as it works)."""
    identities: dict[Annotated[str, Field(pattern=IDENTITY_PATTERN)], Identity]
    grants: tuple[Grant, ...]

    @model_validator(mode="after")
    def _grants_name_identities(self) -> AccessOptions:
        if not self.identities:
            raise ValueError("identities: name at least one identity")
        for i, grant in enumerate(self.grants):
            unknown = [name for name in grant.identities if name not in self.identities]
            if unknown:
                raise ValueError(
                    f"grants[{i}].identities: unknown identity {', '.join(map(repr, unknown))}; "
                    f"identities: {', '.join(sorted(self.identities))}"
                )
        return self

    def unknown_robots(self, robots: tuple[str, ...] | list[str]) -> str | None:
        """The first grant entry naming a robot not in ``robots``, as an error naming its field."""
        for i, grant in enumerate(self.grants):
            for kind, names in (("read", grant.read), ("command", grant.command)):
                for j, name in enumerate(names):
                    if name != ALL_ROBOTS and name not in robots:
                        return (
                            f"zenoh.access.grants[{i}].{kind}[{j}]: {name!r} is not a robot of this cell "
                            f"({', '.join(robots)}; or '*' for all)"
                        )
        return None


class ZenohOptions(Frozen):
    """How the daemon joins the Zenoh network: a peer that clients dial (the default), or a client of
    a Zenoh router that several cells and their clients share (docs/scale-out.md)."""

    mode: Literal["peer", "client", "router"] = "peer"
    listen: tuple[Annotated[str, Field(pattern=ENDPOINT_PATTERN)], ...] = (DEFAULT_ENDPOINT,)
    """Where the daemon accepts sessions; none in ``client`` mode (its clients come through the router)."""
    connect: tuple[Annotated[str, Field(pattern=ENDPOINT_PATTERN)], ...] = ()
    multicast_scouting: bool = False
    low_latency: bool = False
    """Zenoh's low-latency unicast transport (no batching, no QoS priorities): about half the CPU per
    published sample when the subscriber enables it too (``Client.connect(..., low_latency=True)``);
    peers without it still connect. See docs/performance.md."""
    tls: TlsOptions | None = None
    """Certificates for ``tls/`` endpoints; with it every listen endpoint must be ``tls/`` (or
    ``quic/``), so no client gets in around it."""
    access: AccessOptions | None = None
    """Zenoh access control: which identities may read and command which robots."""

    @model_validator(mode="before")
    @classmethod
    def _client_listens_nowhere(cls, data: Any) -> Any:
        """In ``client`` mode ``listen`` defaults to none: the router is where sessions arrive (a
        client listening on the default 7447 would take the port of a router on the same machine)."""
        if isinstance(data, dict) and data.get("mode") == "client" and "listen" not in data:
            return {**data, "listen": ()}
        return data

    @model_validator(mode="after")
    def _client_needs_connect(self) -> ZenohOptions:
        if self.mode == "client":
            self._client_consistent()
        self._tls_consistent()
        return self

    def _client_consistent(self) -> None:
        """A client daemon dials its router, accepts no session, and sees every client of the router
        arrive on its one link to it, so it cannot tell them apart for ``access``."""
        if not self.connect:
            raise ValueError("mode 'client' needs at least one connect endpoint (the router, tcp/HOST:7447)")
        if self.listen:
            raise ValueError(
                f"listen: {list(self.listen)}: a daemon in mode 'client' accepts no sessions (its clients "
                "reach it through the router in 'connect'); leave 'listen' out, or use mode 'peer'"
            )
        if self.access is not None:
            raise ValueError(
                "access: in mode 'client' every client's messages reach the daemon over its one link to "
                "the router, so grants cannot tell clients apart; put access control on the router "
                "(docs/scale-out.md), or use mode 'peer' with clients dialling the daemon"
            )

    def _tls_consistent(self) -> None:
        # Messages start with their own key path, as in Cell: a model validator has no location.
        for field in ("listen", "connect"):
            for i, endpoint in enumerate(getattr(self, field)):
                secure = endpoint.startswith(SECURE_PROTOCOLS)
                if secure and self.tls is None:
                    raise ValueError(
                        f"{field}[{i}]: {endpoint} needs the 'tls' section "
                        "(root_ca, certificate, private_key)"
                    )
                if field == "listen" and self.tls is not None and not secure:
                    raise ValueError(
                        f"listen[{i}]: {endpoint} is not encrypted; with 'tls' every listen endpoint must "
                        "be tls/ or quic/ (this one would let clients in without a certificate)"
                    )
        if self.tls is not None and not any(
            e.startswith(SECURE_PROTOCOLS) for e in self.listen + self.connect
        ):
            raise ValueError("tls: no listen or connect endpoint uses it (tls/HOST:PORT)")
        if self.access is None:
            return
        for name, identity in self.access.identities.items():
            if identity.cert_common_names is not None and (self.tls is None or not self.tls.mutual):
                raise ValueError(
                    f"access.identities.{name}.cert_common_names: clients show a certificate only with "
                    "mutual TLS ('tls' with mutual: true)"
                )
