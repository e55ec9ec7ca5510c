"""Choosing the port a review session listens on, before viser binds it.

viser moves on to the next port when one is taken, but it hangs when it cannot bind
at all (an address this machine does not have, or ports past 65535). So the session
checks here first and hands viser a port that was free a moment ago.
"""

from __future__ import annotations

import errno
import ipaddress
import socket

from ..errors import InputError

__all__ = ["choose_port", "is_loopback", "port_is_free"]


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (only this machine can connect); a name
    other than ``localhost`` counts as reachable from elsewhere."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET


def port_is_free(host: str, port: int) -> bool:
    """Whether ``host:port`` can be listened on now (as the server would, with
    ``SO_REUSEADDR``).

    Raises:
        InputError: ``host`` is not an address of this machine.
    """
    with socket.socket(_family(host), socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except socket.gaierror as exc:
            raise InputError(f"cannot listen on '{host}' ({exc.strerror})", key="host") \
                from None
        except OSError as exc:
            if exc.errno == errno.EACCES:
                raise InputError(f"cannot listen on {host}:{port} ({exc.strerror})",
                                 key="port") from None
            if port == 0 or exc.errno != errno.EADDRINUSE:
                raise InputError(f"cannot listen on '{host}' ({exc.strerror})",
                                 key="host") from None
            return False
        return True


def choose_port(host: str, port: int, *, strict: bool = False) -> int:
    """``port`` if it is free, else the next free one above it (or one the system
    picks); with ``strict``, a taken port is an error.

    Raises:
        InputError: The port is taken and ``strict``; or ``host`` cannot be listened on.
    """
    if port_is_free(host, port):
        return port
    if strict:
        raise InputError(f"port {port} on {host} is in use (another viewer running?); "
                         "pick another with --port", key="port")
    for candidate in range(port + 1, min(port + 100, 65535) + 1):
        if port_is_free(host, candidate):
            return candidate
    with socket.socket(_family(host), socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])

