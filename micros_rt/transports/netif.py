"""This host's network interfaces, as the transports ask about them: which one holds an address, its MTU."""

from __future__ import annotations

import array
import fcntl
import socket
import struct
from typing import Optional

__all__ = ["interface_mtu_of", "interface_of"]

_SIOCGIFADDR = 0x8915
_SIOCGIFMTU = 0x8921


def _request(name: str) -> "array.array[int]":
    return array.array("B", struct.pack("256s", name.encode()[:15]))   # struct ifreq, filled in by the kernel


def interface_of(address: str) -> Optional[str]:
    """The name of the local interface that holds ``address`` (IPv4 or IPv6), or None.

    >>> interface_of("127.0.0.1")
    'lo'
    """
    address = address.split("%", 1)[0]
    if ":" in address:
        try:
            packed = socket.inet_pton(socket.AF_INET6, address).hex()
            with open("/proc/net/if_inet6", encoding="ascii") as f:
                for line in f:
                    words = line.split()
                    if len(words) >= 6 and words[0] == packed:
                        return words[5]
        except OSError:
            return None
        return None
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            for _, name in socket.if_nameindex():
                request = _request(name)
                try:
                    fcntl.ioctl(probe.fileno(), _SIOCGIFADDR, request, True)
                except OSError:
                    continue  # no IPv4 address on it
                if socket.inet_ntoa(request[20:24].tobytes()) == address:
                    return name
    except OSError:
        return None
    return None


def interface_mtu_of(name: str) -> Optional[int]:
    """The MTU of interface ``name``, or None when there is no such interface."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            request = _request(name)
            fcntl.ioctl(probe.fileno(), _SIOCGIFMTU, request, True)
    except OSError:
        return None
    mtu: int = struct.unpack_from("i", request, 16)[0]
    return mtu
