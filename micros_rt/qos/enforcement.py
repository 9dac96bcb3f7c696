"""What a micros_rt subscriber enforces itself, as small pure pieces (no threads, no I/O).

DDS enforces time filter and lifespan inside Cyclone for DDS links; a TCPROS link has neither, and a
sample taken from Cyclone can still wait behind slow callbacks. The subscription applies these to
every message right before its callbacks, whatever the transport.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

__all__ = ["TimeFilter", "SourceOrder", "DeadlineMonitor", "DeadlineMissed", "ClockSkewCheck", "CLOCK_SKEW_WARN_SECONDS",
           "is_expired"]

#: A writer whose samples arrive stamped further than this from our clock is reported (once).
CLOCK_SKEW_WARN_SECONDS = 1.0


@dataclass(frozen=True)
class DeadlineMissed:
    """Given to ``deadline_cb``: the topic, the deadline and how long it has been silent."""

    topic: str
    deadline: float
    silent_for: float
    total_count: int


class TimeFilter:
    """At most one message per ``period`` seconds (``time_filter_duration``); 0 lets everything through.

    >>> f = TimeFilter(1.0)
    >>> [f.admit(t) for t in (0.0, 0.5, 1.0, 1.2)]
    [True, False, True, False]
    """

    __slots__ = ("period", "_last")

    def __init__(self, period: float) -> None:
        self.period = period
        self._last = -math.inf

    def admit(self, now: float) -> bool:
        if self.period <= 0.0:
            return True
        if now - self._last < self.period:
            return False
        self._last = now
        return True


class SourceOrder:
    """``ordered_by_sending_timestamp``: a message stamped before the last one admitted is dropped, as a DDS
    reader ordered BY_SOURCE_TIMESTAMP drops it (one instance: every publisher of the topic together).
    Unstamped messages (0) pass and do not move the mark; ``enabled`` False lets everything through.

    >>> o = SourceOrder(True)
    >>> [o.admit(t) for t in (10, 12, 11, 0, 12, 13)]
    [True, True, False, True, True, True]
    """

    __slots__ = ("enabled", "_last")

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self._last = 0

    def admit(self, source_ns: int) -> bool:
        if not self.enabled or not source_ns:
            return True
        if source_ns < self._last:
            return False
        self._last = source_ns
        return True


class DeadlineMonitor:
    """Silence longer than ``deadline`` seconds is a miss, reported once per ``deadline`` of silence.

    ``poll(now)`` returns the silent time when a miss is due; ``delivered(now)`` records a message and
    returns how long the silence lasted if it had missed the deadline (for a "data resumed" report).

    >>> d = DeadlineMonitor(0.5, start=0.0)
    >>> d.poll(0.4), d.poll(0.6), d.poll(0.7), d.delivered(2.0)
    (None, 0.6, None, 2.0)
    """

    __slots__ = ("deadline", "_last_delivery", "_last_report", "_missing", "missed_total")

    def __init__(self, deadline: float, *, start: float) -> None:
        self.deadline = deadline
        self._last_delivery = start
        self._last_report = start
        self._missing = False
        self.missed_total = 0

    @property
    def enabled(self) -> bool:
        return math.isfinite(self.deadline)

    def poll(self, now: float) -> Optional[float]:
        if not self.enabled or now - self._last_report < self.deadline:
            return None
        self._last_report = now
        self._missing = True
        self.missed_total += 1
        return now - self._last_delivery

    def delivered(self, now: float) -> Optional[float]:
        silent = now - self._last_delivery
        self._last_delivery = self._last_report = now
        if self._missing:
            self._missing = False
            return silent
        return None


def is_expired(source_ns: int, now_ns: int, valid_period: float) -> bool:
    """True when a sample stamped ``source_ns`` is older than ``valid_period`` seconds (msg_valid_period).

    >>> is_expired(0, 2_000_000_000, 1.0), is_expired(0, 2_000_000_000, math.inf)
    (True, False)
    """
    return math.isfinite(valid_period) and now_ns - source_ns > valid_period * 1e9


class ClockSkewCheck:
    """Judges one writer's clock from the age of its first samples (source stamp to arrival).

    A sample's age is the clock offset plus its latency, which queueing only makes longer. So a sample
    stamped in the future means a clock ahead at once; a clock behind is the *smallest* age among the
    first ``samples`` ones *and* the first ``window`` seconds of arrivals: a backlog (a node starved of CPU
    while many start, a link that held its queue) arrives in a burst of old samples, and only after it has
    drained do the ages show the offset. ``observe`` returns the skew in seconds (positive: the writer is
    behind, or every sample in the window waited that long) once, when it is beyond ``limit``; ``done``
    turns True when the writer is judged either way.
    """

    __slots__ = ("limit", "samples", "window", "_n", "_lowest", "_first", "done")

    def __init__(self, limit: float = CLOCK_SKEW_WARN_SECONDS, samples: int = 10, window: float = 1.5) -> None:
        self.limit = limit
        self.samples = samples
        self.window = window
        self._n = 0
        self._lowest = math.inf
        self._first: Optional[float] = None
        self.done = False

    def observe(self, age_ns: int, now: float) -> Optional[float]:
        """One sample's age (ns) on arrival at ``now`` (any monotonic clock, in seconds)."""
        if self.done:
            return None
        self._n += 1
        self._lowest = min(self._lowest, age_ns)
        if self._first is None:
            self._first = now
        limit_ns = self.limit * 1e9
        if age_ns < -limit_ns:
            self.done = True
            return age_ns / 1e9
        if self._n >= self.samples and now - self._first >= self.window:
            self.done = True
            if self._lowest > limit_ns:
                return self._lowest / 1e9
        return None
