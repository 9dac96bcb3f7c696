"""Priority in the receiver: when a node's CPU is the bottleneck, HIGH topics' callbacks run first.

A subscription's delivery thread runs its topic's callbacks. It takes the transport priority of the
highest publisher it receives from over DDS (micros_rt publishers send their QoS in the negotiation) and
the OS and the interpreter are told:

- **The OS**: the thread's nice value (Linux: per thread, ``setpriority`` on its native id). HIGH and
  above run at nice -5 (where the process may: CAP_SYS_NICE or root; else they stay at 0), LOW and below at
  +5 (always allowed), NORMAL at 0. Under CFS a nice -5 thread gets about 3x the CPU share of a nice 0 one
  and 10x of a nice +5 one when both are runnable. Real-time scheduling (SCHED_FIFO/RR) is not used: a
  Python thread at a real-time priority that holds the GIL in a long callback would starve every other
  thread of the process, Cyclone's receive thread included, and on a 2-core robot computer the rest of it.
- **The interpreter**: CPython runs one thread's Python code at a time. A thread that wants the GIL asks
  the holder to let go, which it does after ``sys.getswitchinterval()`` (5 ms by default): a HIGH callback
  waits up to that long behind a LOW topic's image processing, every time. While the process receives a
  HIGH topic the interval is 1 ms (restored when the last such subscription closes). The GIL itself has
  no priorities: after a forced switch any waiting thread may take it, the OS priority only makes it more
  likely that the HIGH thread is the one running. Work that releases the GIL (numpy, OpenCV, I/O) is
  where the OS priority has its full effect.

``MICROS_RT_RECEIVE_PRIORITY=0`` turns both off (a node that sets its own thread priorities).
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Mapping, Optional

from .. import settings
from ..log import nonblocking_logger
from ..qos import TransportPriority

__all__ = ["HIGH_SWITCH_INTERVAL", "enabled", "nice_for", "set_thread_nice", "ReceivePriority"]

_log = nonblocking_logger("rosout.micros_rt")

#: The interpreter's switch interval while a HIGH topic is received (seconds).
HIGH_SWITCH_INTERVAL = 0.001
HIGH_NICE = -5
LOW_NICE = 5


def enabled(env: Mapping[str, str] = os.environ) -> bool:
    return settings.RECEIVE_PRIORITY.get(env)


def nice_for(priority: TransportPriority) -> int:
    """The nice value a delivery thread of ``priority`` runs at."""
    if priority >= TransportPriority.HIGH:
        return HIGH_NICE
    if priority <= TransportPriority.LOW:
        return LOW_NICE
    return 0


def set_thread_nice(nice: int, tid: Optional[int] = None) -> int:
    """Give the calling thread (or thread ``tid``) ``nice``; returns the nice it has afterwards.

    A negative value the process may not set (no CAP_SYS_NICE) leaves the thread at 0 and says so once."""
    tid = threading.get_native_id() if tid is None else tid
    try:
        os.setpriority(os.PRIO_PROCESS, tid, nice)
    except PermissionError:
        if nice < 0:
            _warn_no_nice_once()
            try:
                os.setpriority(os.PRIO_PROCESS, tid, 0)
            except OSError:
                pass
    except OSError as exc:  # the thread is gone, or not Linux semantics
        _log.debug("micros_rt: could not set thread %d's priority: %s", tid, exc)
    try:
        return os.getpriority(os.PRIO_PROCESS, tid)
    except OSError:
        return 0


_warned = False


def _warn_no_nice_once() -> None:
    global _warned
    if not _warned:
        _warned = True
        _log.info("micros_rt: HIGH topics' delivery threads stay at nice 0: raising a thread's priority needs "
                  "CAP_SYS_NICE (e.g. `setcap cap_sys_nice+ep` on the interpreter, or a higher RLIMIT_NICE); "
                  "LOW topics' threads still run at nice %d", LOW_NICE)


class ReceivePriority:
    """The process's count of subscriptions receiving a HIGH topic, and the switch interval it implies."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._high = 0
        self._saved: Optional[float] = None

    @property
    def high(self) -> int:
        return self._high

    def enter_high(self) -> None:
        with self._lock:
            self._high += 1
            if self._high == 1:
                self._saved = sys.getswitchinterval()
                if self._saved > HIGH_SWITCH_INTERVAL:
                    sys.setswitchinterval(HIGH_SWITCH_INTERVAL)

    def leave_high(self) -> None:
        with self._lock:
            if self._high == 0:
                return
            self._high -= 1
            if self._high == 0 and self._saved is not None:
                # only undo our own change: a node that set its own interval meanwhile keeps it
                if abs(sys.getswitchinterval() - HIGH_SWITCH_INTERVAL) < 1e-7:
                    sys.setswitchinterval(self._saved)
                self._saved = None


#: One per process (the switch interval is the interpreter's).
RECEIVE_PRIORITY = ReceivePriority()
