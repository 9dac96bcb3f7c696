"""Transport priority on a socket: the one place micros_rt sets IP TOS (DSCP) and SO_PRIORITY.

Every transport marks its sockets through :func:`mark_socket`: TCPROS links per connection, Cyclone's
UDP sockets, the MQTT connection and the microcontroller link. IPv4 gets ``IP_TOS``, IPv6
``IPV6_TCLASS``; then ``SO_PRIORITY`` picks the local queueing band (set after IP_TOS, which overwrites
it on Linux). Unix sockets carry no TOS and are left alone. NORMAL (TOS 0) leaves a socket as it is
unless ``force`` asks to reset an earlier marking.
"""

from __future__ import annotations

import socket
from typing import List, Optional, Tuple

from ..qos.options import TransportPriority, priority_socket_priority, priority_tos

__all__ = ["mark_socket", "mark_socket_tos", "tos_options"]


def tos_options(tos: int, so_priority: Optional[int], family: int) -> List[Tuple[int, int, int]]:
    """The ``(level, option, value)`` settings that mark a socket of ``family`` with ``tos`` (and ``so_priority``
    when given); empty for a family that carries no TOS (unix)."""
    if family == socket.AF_INET6:
        options = [(socket.IPPROTO_IPV6, socket.IPV6_TCLASS, tos)]
    elif family == socket.AF_INET:
        options = [(socket.IPPROTO_IP, socket.IP_TOS, tos)]
    else:
        return []
    if so_priority is not None and hasattr(socket, "SO_PRIORITY"):
        options.append((socket.SOL_SOCKET, socket.SO_PRIORITY, so_priority))
    return options


def mark_socket_tos(sock: socket.socket, tos: int, so_priority: Optional[int] = None, *,
                    family: Optional[int] = None) -> bool:
    """Set ``tos`` (and ``so_priority`` when given) on ``sock``; returns False for a socket that carries
    no TOS (unix). Raises ``OSError`` when the kernel refuses."""
    options = tos_options(tos, so_priority, sock.family if family is None else family)
    for level, option, value in options:
        sock.setsockopt(level, option, value)
    return bool(options)


def mark_socket(sock: socket.socket, priority: TransportPriority, *, force: bool = False,
                family: Optional[int] = None) -> bool:
    """Mark ``sock`` with ``priority``'s DSCP and socket priority.

    >>> s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    >>> mark_socket(s, TransportPriority.HIGH), s.getsockopt(socket.IPPROTO_IP, socket.IP_TOS)
    (True, 136)
    >>> s.close()

    Returns True when the socket was marked, False when there was nothing to do (NORMAL without
    ``force``, or a unix socket). Raises ``OSError`` when the kernel refuses.
    """
    if priority == TransportPriority.NORMAL and not force:
        return False
    return mark_socket_tos(sock, priority_tos(priority), priority_socket_priority(priority), family=family)
