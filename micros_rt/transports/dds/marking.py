"""Transport priority on the wire for DDS: IP TOS (DSCP) on Cyclone's UDP sockets.

Cyclone DDS 11 carries TransportPriority in discovery only and has no setting for
DSCP or IP_TOS. Its sockets live in our process, though, so micros_rt marks them
itself: the UDP sockets that appeared while a participant was created are
Cyclone's (its receive sockets on the DDSI ports and its transmit socket on an
ephemeral port); ``IP_TOS`` (then ``SO_PRIORITY``) is set on them.

Cyclone sends all data of a participant through the same sockets, so a marking is per
participant, not per writer. A process's first DDS writer marks the process participant
(which also carries its readers' acknowledgements and its discovery); a writer of another
transport priority gets a participant of its own for that priority, with its own sockets
(:func:`micros_rt.transports.dds.participant.priority_participant`). Each DDS topic then
leaves with its own priority's DSCP, as each TCPROS connection does.
"""

from __future__ import annotations

import logging
import os
import socket
import stat
from typing import Callable, Dict, Set, Tuple
from ...log import nonblocking_logger
from ..marking import mark_socket_tos

__all__ = ["process_udp_sockets", "mark_udp_sockets", "limit_send_buffers"]

_log = nonblocking_logger("rosout.micros_rt.dds")


def process_udp_sockets() -> Dict[int, Tuple[int, int]]:
    """inode -> (fd, family) of this process's UDP sockets (IPv4 and IPv6).

    Each open descriptor that is a socket (``fstat``) is asked its family and type by the kernel (a socket
    made on a duplicate of it: the standard library reads ``SO_DOMAIN``/``SO_TYPE``); its inode is the
    ``socket:[inode]`` Linux shows. No text of /proc/net/udp is parsed."""
    found: Dict[int, Tuple[int, int]] = {}
    try:
        fds = os.listdir("/proc/self/fd")
    except OSError:
        return found
    for name in fds:
        fd = int(name)
        try:
            st = os.fstat(fd)
        except OSError:  # the listing's own descriptor, or one closed meanwhile
            continue
        if not stat.S_ISSOCK(st.st_mode):
            continue
        try:
            probe = socket.socket(fileno=os.dup(fd))
        except OSError:
            continue
        with probe:
            if probe.type == socket.SOCK_DGRAM and probe.family in (socket.AF_INET, socket.AF_INET6):
                found[st.st_ino] = (fd, int(probe.family))
    return found


def mark_udp_sockets(inodes: Set[int], tos: int, so_priority: int) -> int:
    """Set IP_TOS/IPV6_TCLASS and SO_PRIORITY on the UDP sockets with these inodes; returns how many."""
    return _each_udp_socket(inodes, lambda s, family: mark_socket_tos(s, tos, so_priority, family=family),
                            f"mark a DDS socket with TOS 0x{tos:02x}")


def limit_send_buffers(inodes: Set[int], size: int) -> int:
    """Set SO_SNDBUF to ``size`` (the kernel doubles it) on the UDP sockets with these inodes; returns how many."""
    def limit(s: socket.socket, _family: int) -> bool:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, size)
        return True

    return _each_udp_socket(inodes, limit, f"give a DDS socket a send buffer of {size} bytes")


def _each_udp_socket(inodes: Set[int], apply: Callable[[socket.socket, int], bool], what: str) -> int:
    done = 0
    for inode, (fd, family) in process_udp_sockets().items():
        if inode not in inodes:
            continue
        try:
            # fromfd duplicates the descriptor: options apply to the shared socket, and
            # closing the duplicate leaves Cyclone's descriptor open.
            s = socket.fromfd(fd, family, socket.SOCK_DGRAM)
        except OSError:
            continue
        try:
            if apply(s, family):
                done += 1
        except OSError as exc:
            _log.warning("micros_rt: cannot %s: %s", what, exc)
        finally:
            s.close()
    return done
