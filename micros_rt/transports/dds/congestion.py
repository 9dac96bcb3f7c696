"""Whether a participant's transmit socket is congested: large writes that waited for socket room.

Cyclone sends all data of a participant through one transmit socket per interface. A large write that waits
for room in it (a slow link drains it) holds up every later write through the same socket, a small one's
``sendmsg`` included. :class:`SocketCongestion` remembers that, per participant: while it lasts, every write
of that participant releases Python's GIL, and the send queues of its KEEP_LAST writers send from their own
threads. Writers on another participant (another transport priority, see
:func:`~micros_rt.transports.dds.participant.priority_participant`) have their own socket and are not held
up by it.
"""

from __future__ import annotations

import ctypes
import time
from typing import Any, Callable, List, Set

from .batching import c_function

__all__ = ["SocketCongestion", "RELEASED_WRITE_MIN", "CONGESTED_WRITE", "CONGESTION_HOLD"]

#: Samples at least this large (bytes) are written with Python's GIL released (:meth:`SocketCongestion.write_released`).
RELEASED_WRITE_MIN = 16 * 1024

#: A write through :meth:`SocketCongestion.write_released` that took longer than this (s) waited for room in a socket that a
#: slow link drains: the participant's transmit socket is congested for :data:`CONGESTION_HOLD` seconds, and
#: meanwhile every write of that participant releases the GIL and KEEP_LAST send queues send from their threads.
CONGESTED_WRITE = 0.005
CONGESTION_HOLD = 0.1


class _SampleContainer(ctypes.Structure):
    # cyclonedds-python's sample as its sertype reads it (clayer/pysertype.c, ddspy_sample_container_t):
    # the serialized bytes, copied into a serdata in C (serdata_from_sample is a memcpy, no Python)
    _fields_ = [("usample", ctypes.c_void_p), ("usample_size", ctypes.c_size_t)]


_c_dds_write: Any = None


def _released_call(ref: int, data: Any) -> int:
    """``dds_write(ref, data)`` through ctypes, which releases the GIL during the call."""
    global _c_dds_write
    fn = _c_dds_write
    if fn is None:
        fn = _c_dds_write = c_function("dds_write", [ctypes.c_int32, ctypes.c_void_p], ctypes.c_int32)
    if isinstance(data, bytes):
        address = ctypes.cast(ctypes.c_char_p(data), ctypes.c_void_p).value
    else:  # the codec's bytearray (writable: ctypes views it without a copy)
        address = ctypes.addressof((ctypes.c_char * len(data)).from_buffer(data))
    return int(fn(ref, ctypes.byref(_SampleContainer(address, len(data)))))


class SocketCongestion:
    """One participant's transmit socket: congested while a recent large write waited on the network."""

    __slots__ = ("until", "last_slow", "slow_writers")

    def __init__(self) -> None:
        self.until: List[float] = [0.0]  # monotonic time until which the socket counts as congested
        self.last_slow = 0.0  # how long the last large write that waited took (0.0: it did not wait)
        self.slow_writers: Set[int] = set()  # writers whose last large write waited on the network

    def active(self) -> bool:
        """True while a recent large write waited on the network (see :data:`CONGESTED_WRITE`)."""
        return time.monotonic() < self.until[0]

    def network_bound(self, ref: int) -> bool:
        """True when writer ``ref``'s last large write waited on the network (a slow link drains its socket)."""
        return ref in self.slow_writers

    def forget(self, ref: int) -> None:
        self.slow_writers.discard(ref)

    def write_released(self, ref: int, data: Any) -> int:
        """``ddspy_write(ref, data)`` without holding Python's GIL: the binding's own call holds it for the whole
        of ``dds_write``, which for a large sample includes sending every fragment, and a ``sendmsg`` that
        waits for room in a socket buffer behind a slow link (measured: a 1 kHz topic of the same process
        published 117 of 6,000 messages beside a 30 Hz camera on a 40 Mbit/s link). ~1 us more per call than
        the binding's, so only for large samples and while the socket is congested."""
        t0 = time.monotonic()
        if self.last_slow:  # it will likely wait as long again: congested from now on, not from its end
            self.until[0] = max(self.until[0], t0 + self.last_slow + CONGESTION_HOLD)
        ret = _released_call(ref, data)
        done = time.monotonic()
        if len(data) >= RELEASED_WRITE_MIN:
            took = done - t0
            if took > CONGESTED_WRITE:
                self.last_slow = took
                self.slow_writers.add(ref)
                self.until[0] = max(self.until[0], done + CONGESTION_HOLD)
            else:
                self.last_slow = 0.0
                self.slow_writers.discard(ref)
        return ret

    def sample_write(self, small: Callable[[int, Any], int]) -> Callable[[int, Any], int]:
        """``write(ref, data)`` for this participant's writers: the binding's fast call ``small`` for small
        samples, :meth:`write_released` for large ones and for every one while the socket is congested."""
        until, released, now = self.until, self.write_released, time.monotonic

        def sample_write(ref: int, data: Any, _limit: int = RELEASED_WRITE_MIN) -> int:
            if len(data) < _limit and now() >= until[0]:
                return small(ref, data)
            return released(ref, data)

        return sample_write

