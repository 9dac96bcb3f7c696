"""Transport priority on a socket: the one place micros_rt sets IP TOS (DSCP) and SO_PRIORITY.

Every transport marks its sockets through :func:`mark_socket`: TCPROS links per connection, Cyclone's
UDP sockets, the MQTT connection and the microcontroller link. IPv4 gets ``IP_TOS``, IPv6
``IPV6_TCLASS``; then ``SO_PRIORITY`` picks the local queueing band (set after IP_TOS, which overwrites
it on Linux). Unix sockets carry no TOS and are left alone. NORMAL (TOS 0) leaves a socket as it is
unless ``force`` asks to reset an earlier marking.
"""

from __future__ import annotations

import socket
from typing import Optional

from ..qos.options import TransportPriority, priority_socket_priority, priority_tos

__all__ = ["mark_socket", "mark_socket_tos"]


def mark_socket_tos(sock: socket.socket, tos: int, so_priority: Optional[int] = None, *,
                    family: Optional[int] = None) -> bool:
    """Set ``tos`` (and ``so_priority`` when given) on ``sock``; returns False for a socket that carries
    no TOS (unix). Raises ``OSError`` when the kernel refuses."""
    family = sock.family if family is None else family
    if family == socket.AF_INET6:
        sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_TCLASS, tos)
    elif family == socket.AF_INET:
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_TOS, tos)
    else:
        return False
    if so_priority is not None and hasattr(socket, "SO_PRIORITY"):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_PRIORITY, so_priority)
    return True


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
