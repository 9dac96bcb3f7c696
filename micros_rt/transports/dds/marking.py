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

import ctypes
import ctypes.util
import os
import socket
import stat
from typing import Callable, Dict, List, Optional, Set, Tuple
from ...log import nonblocking_logger
from ..marking import tos_options

__all__ = ["process_udp_sockets", "mark_udp_sockets", "limit_send_buffers"]

_log = nonblocking_logger("rosout.micros_rt.dds")

# Cyclone's descriptors (and rospy's, which the scan passes over) are read and set through the C library on the
# descriptor itself: a Python socket object made on a duplicate shares the open file, and once rospy has set a
# default socket timeout (it does, 60 s, when a subscriber connects) making one switches that file to
# non-blocking. Every socket of the process went so, rospy's TCPROS server among them, whose accept thread then
# died of EAGAIN: no subscriber could connect to the node any more (a CI-like run: 1 PoseStamped of 10 through the
# MQTT bridge, the bridge's log ending in "BlockingIOError: [Errno 11]" in rospy's tcpros_base)
_libc: Optional[ctypes.CDLL] = None


def _c() -> ctypes.CDLL:
    global _libc
    if _libc is None:
        _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    return _libc


def _getsockopt_int(fd: int, level: int, option: int) -> int:
    value, size = ctypes.c_int(0), ctypes.c_uint32(ctypes.sizeof(ctypes.c_int))
    if _c().getsockopt(fd, level, option, ctypes.byref(value), ctypes.byref(size)) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))
    return value.value


def _setsockopt_int(fd: int, level: int, option: int, value: int) -> None:
    v = ctypes.c_int(value)
    if _c().setsockopt(fd, level, option, ctypes.byref(v), ctypes.sizeof(v)) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


def process_udp_sockets() -> Dict[int, Tuple[int, int]]:
    """inode -> (fd, family) of this process's UDP sockets (IPv4 and IPv6).

    Each open descriptor that is a socket (``fstat``) is asked its family and type by the kernel
    (``SO_DOMAIN``/``SO_TYPE`` on the descriptor, which changes nothing on it); its inode is the
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
            family = _getsockopt_int(fd, socket.SOL_SOCKET, socket.SO_DOMAIN)
            kind = _getsockopt_int(fd, socket.SOL_SOCKET, socket.SO_TYPE)
        except OSError:
            continue
        if kind == socket.SOCK_DGRAM and family in (socket.AF_INET, socket.AF_INET6):
            found[st.st_ino] = (fd, family)
    return found


def mark_udp_sockets(inodes: Set[int], tos: int, so_priority: int) -> int:
    """Set IP_TOS/IPV6_TCLASS and SO_PRIORITY on the UDP sockets with these inodes; returns how many."""
    return _each_udp_socket(inodes, lambda family: tos_options(tos, so_priority, family),
                            f"mark a DDS socket with TOS 0x{tos:02x}")


def limit_send_buffers(inodes: Set[int], size: int) -> int:
    """Set SO_SNDBUF to ``size`` (the kernel doubles it) on the UDP sockets with these inodes; returns how many."""
    return _each_udp_socket(inodes, lambda _family: [(socket.SOL_SOCKET, socket.SO_SNDBUF, size)],
                            f"give a DDS socket a send buffer of {size} bytes")


def _each_udp_socket(inodes: Set[int], options: Callable[[int], List[Tuple[int, int, int]]], what: str) -> int:
    """Apply ``options(family)`` (``(level, option, value)`` each) to the UDP sockets with these inodes, on their
    descriptors; returns how many got them all."""
    done = 0
    for inode, (fd, family) in process_udp_sockets().items():
        if inode not in inodes:
            continue
        wanted = options(family)
        try:
            for level, option, value in wanted:
                _setsockopt_int(fd, level, option, value)
        except OSError as exc:
            _log.warning("micros_rt: cannot %s: %s", what, exc)
            continue
        if wanted:
            done += 1
    return done
