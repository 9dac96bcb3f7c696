"""Marking Cyclone's UDP sockets from Python leaves every other socket of the process as it was.

micros_rt finds and marks a participant's sockets by scanning the process's descriptors. It used to wrap each in a
Python socket object; once rospy had set a default socket timeout (60 s, when a subscriber connects), that made
the shared open file non-blocking, rospy's TCPROS accept thread died of EAGAIN and the node took no more
subscribers."""

from __future__ import annotations

import fcntl
import os
import socket
from typing import Iterator

import pytest

from micros_rt.transports.dds.marking import limit_send_buffers, mark_udp_sockets, process_udp_sockets


def nonblocking(sock: socket.socket) -> bool:
    return bool(fcntl.fcntl(sock.fileno(), fcntl.F_GETFL) & os.O_NONBLOCK)


@pytest.fixture
def default_timeout() -> Iterator[None]:
    old = socket.getdefaulttimeout()
    socket.setdefaulttimeout(60.0)  # what rospy does
    try:
        yield
    finally:
        socket.setdefaulttimeout(old)


def test_the_scan_and_the_marks_leave_blocking_sockets_blocking(default_timeout: None) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp, \
            socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as udp6:
        for s in (server, udp, udp6):
            s.setblocking(True)
        server.bind(("127.0.0.1", 0))
        server.listen()
        found = process_udp_sockets()
        inode = os.fstat(udp.fileno()).st_ino
        assert found[inode] == (udp.fileno(), socket.AF_INET)
        assert found[os.fstat(udp6.fileno()).st_ino] == (udp6.fileno(), socket.AF_INET6)
        assert os.fstat(server.fileno()).st_ino not in found  # TCP is not Cyclone's
        assert mark_udp_sockets({inode, os.fstat(udp6.fileno()).st_ino}, 0x88, 5) == 2
        assert limit_send_buffers({inode}, 65536) == 1
        assert udp.getsockopt(socket.IPPROTO_IP, socket.IP_TOS) == 0x88
        assert udp6.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_TCLASS) == 0x88
        assert udp.getsockopt(socket.SOL_SOCKET, socket.SO_PRIORITY) == 5
        assert udp.getsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF) >= 65536
        assert not any(nonblocking(s) for s in (server, udp, udp6))
