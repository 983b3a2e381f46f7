"""Where a UR robot's four callback servers listen, and the address its control program dials.

By default (no ``ur.listen_address``) the servers listen only on the address of this machine's
interface that reaches the robot, never on every interface (0.0.0.0): the kernel's route to the
robot's IP names it (``interface_toward``: a UDP socket's ``connect`` picks the source address and
sends nothing). A robot on this machine (a fake on 127.x.y.z, URSim on loopback) connects from its
own loopback address, which the kernel's route does not name (it answers 127.0.0.1 for all of
127.0.0.0/8): there the servers listen on the robot's own address.

``ur.reverse_ip`` is the address the robot connects back to, so listening anywhere else would leave
the program nothing to reach: when it is an address of this machine the servers listen there. When
it is not (an address forwarded to this machine, e.g. a port published by a container host), they
listen on the interface that reaches the robot, where the forwarded connections arrive.

An explicit ``ur.listen_address`` is taken as it is (0.0.0.0 or :: listens on every interface).
Both IPv4 and IPv6 robot addresses are handled; an IPv6 link-local source keeps its scope.

Everything here may block (name resolution): the backend calls ``listen_plan`` in a thread, ``urdaemon
check`` directly.
"""

from __future__ import annotations

import errno
import ipaddress
import socket
from dataclasses import dataclass

from urdaemon.cell.robot_options import UrOptions
from urdaemon.errors import BackendError

__all__ = ["ListenPlan", "interface_toward", "is_local_address", "listen_plan", "robot_ip"]

_DISCARD_PORT = 9
"""The port a routing probe's UDP socket is connected to (nothing is ever sent to it)."""


@dataclass(frozen=True)
class ListenPlan:
    """Where one robot's callback servers listen, and why."""

    address: str
    """The address the servers listen on."""
    robot_ip: str
    """The robot's IP address (its host name resolved): the only address they accept connections from."""
    connect_back: str
    """The address the control program dials; "" when it is learnt later (the daemon's end of its
    RTDE connection, as when the servers listen on every interface)."""
    why: str
    """Why there, for the log: "the interface that reaches the robot at 10.0.0.20"."""


def robot_ip(host: str) -> str:
    """The robot's IP address: ``host`` if it is one, else the first address its name resolves to for
    a TCP connection (the one a connection to it tries first); BackendError if it does not resolve."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        pass
    try:
        found = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as err:
        raise BackendError(f"the robot's address {host!r} does not resolve: {err}") from None
    return str(found[0][4][0])


def interface_toward(ip: str) -> str:
    """The address of this machine's interface that reaches ``ip`` (an IP address); the robot's own
    address when it is a loopback one (see the module's docstring). BackendError if no route leads
    there."""
    address = ipaddress.ip_address(ip)
    if address.is_loopback:
        return ip
    if address.is_unspecified or address.is_multicast:
        raise BackendError(f"the robot's address {ip} is not one a robot can have")
    family = socket.AF_INET6 if address.version == 6 else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect((ip, _DISCARD_PORT))  # picks the route and its source address; sends nothing
        except OSError as err:
            raise BackendError(
                f"no route from this machine to the robot at {ip}: {err.strerror or err} "
                "(check the network, or set ur.listen_address)"
            ) from None
        name = probe.getsockname()
    local = str(name[0])
    if family == socket.AF_INET6 and name[3] and "%" not in local:
        local = f"{local}%{name[3]}"  # a link-local source is bound with its interface
    return local


def is_local_address(host: str) -> bool:
    """Whether this machine can listen on ``host`` (an IP address or host name): it is one of its own."""
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as sock:
            sock.bind((host, 0))
    except OSError as err:
        if err.errno == errno.EADDRNOTAVAIL or isinstance(err, socket.gaierror):
            return False
        raise BackendError(f"cannot tell whether {host} is an address of this machine: {err}") from None
    return True


def listen_plan(robot_host: str, options: UrOptions) -> ListenPlan:
    """Where the servers of the robot at ``robot_host`` listen under ``options`` (see the module's
    docstring); BackendError (one line) if the robot's address does not resolve or has no route."""
    ip = robot_ip(robot_host)
    reverse_ip = options.reverse_ip
    if options.listen_address is not None:
        given = options.listen_address
        back = reverse_ip or (given if _specific_ip(given) else "")
        return ListenPlan(given, ip, back, "as ur.listen_address says")
    route = interface_toward(ip)
    why = f"the interface that reaches the robot at {ip}"
    if reverse_ip is None or reverse_ip == route:
        return ListenPlan(route, ip, route, why)
    if is_local_address(reverse_ip):
        why = f"ur.reverse_ip, the address the robot connects back to ({why} is {route})"
        return ListenPlan(reverse_ip, ip, reverse_ip, why)
    return ListenPlan(
        route, ip, reverse_ip, f"{why} (ur.reverse_ip {reverse_ip} is not this machine's: forwarded here)"
    )


def _specific_ip(host: str) -> bool:
    """Whether ``host`` is one IP address (not a host name, not 0.0.0.0 or ::)."""
    try:
        return not ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False
