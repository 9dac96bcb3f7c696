"""What a micros_rt subscriber enforces itself, as small pure pieces (no threads, no I/O).

DDS enforces time filter and lifespan inside Cyclone for DDS links; a TCPROS link has neither, and a
sample taken from Cyclone can still wait behind slow callbacks. The subscription applies these to
every message right before its callbacks, whatever the transport.

An enforced option's check is an :class:`Admission`: made from the option's value by its catalogue entry
(:data:`micros_rt.qos.options.OPTIONS`, ``admission``), it says whether the option asks for anything
(:meth:`Admission.active`), judges one message (:meth:`Admission.check`) and counts what it drops in the statistics
field the entry names. The subscription loops over the active ones, in :attr:`Admission.rank` order, and over
nothing else; adding an enforced option is its entry and its Admission.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Optional

__all__ = ["Admission", "TimeFilter", "SourceOrder", "Lifespan", "DeadlineMonitor", "DeadlineMissed",
           "ClockSkewCheck", "CLOCK_SKEW_WARN_SECONDS", "is_expired"]


class Admission:
    """One enforced option's check on one subscription. ``enforcer``: its name in the catalogue (what a transport
    reader that applies it natively lists in ``enforces``); ``counter``: the statistics field of its drops;
    ``dropped``: its drops so far (the subscription counts them)."""

    __slots__ = ("enforcer", "counter", "dropped")
    #: checks run in rank order (a cheap one that must see every message first: source order, then time filter)
    rank = 50

    def __init__(self) -> None:
        self.enforcer = ""
        self.counter = ""
        self.dropped = 0

    def active(self) -> bool:
        """Whether the option asks for this check now (else the subscription skips it)."""
        return True

    def check(self, sent_ns: int, source_ns: int, qos: Any) -> bool:
        """Whether one message passes: ``sent_ns`` its sending time when the link carries one (else 0),
        ``source_ns`` that or its Header stamp (0: none), ``qos`` its publisher's AdvertiseQoSOptions when known."""
        return True

#: A writer whose samples arrive stamped further than this from our clock is reported (once).
CLOCK_SKEW_WARN_SECONDS = 1.0


@dataclass(frozen=True)
class DeadlineMissed:
    """Given to ``deadline_cb``: the topic, the deadline and how long it has been silent."""

    topic: str
    deadline: float
    silent_for: float
    total_count: int


class TimeFilter(Admission):
    """At most one message per ``period`` seconds (``time_filter_duration``); 0 lets everything through.

    >>> f = TimeFilter(1.0)
    >>> [f.admit(t) for t in (0.0, 0.5, 1.0, 1.2)]
    [True, False, True, False]
    """

    __slots__ = ("period", "_last")
    rank = 20

    def __init__(self, period: float) -> None:
        super().__init__()
        self.period = period
        self._last = -math.inf

    def active(self) -> bool:
        return self.period > 0.0

    def check(self, sent_ns: int, source_ns: int, qos: Any) -> bool:
        if self.period <= 0.0:
            return True
        now = time.time()  # by arrival, as Cyclone's TimeBasedFilter on the reader
        if now - self._last < self.period:
            return False
        self._last = now
        return True

    def admit(self, now: float) -> bool:
        if self.period <= 0.0:
            return True
        if now - self._last < self.period:
            return False
        self._last = now
        return True


class SourceOrder(Admission):
    """``ordered_by_sending_timestamp``: a message stamped before the last one admitted is dropped, as a DDS
    reader ordered BY_SOURCE_TIMESTAMP drops it (one instance: every publisher of the topic together).
    Unstamped messages (0) pass and do not move the mark; ``enabled`` False lets everything through. As a
    subscription's check it goes by the sending time only (a Header stamp is when the data was taken, and
    publishers of one topic legitimately send data stamped out of order: tf), and first: an out-of-order
    message must not use up the time filter's window.

    >>> o = SourceOrder(True)
    >>> [o.admit(t) for t in (10, 12, 11, 0, 12, 13)]
    [True, True, False, True, True, True]
    """

    __slots__ = ("enabled", "_last")
    rank = 10

    def __init__(self, enabled: bool) -> None:
        super().__init__()
        self.enabled = enabled
        self._last = 0

    def active(self) -> bool:
        return self.enabled

    def check(self, sent_ns: int, source_ns: int, qos: Any) -> bool:
        if not sent_ns:
            return True
        if sent_ns < self._last:
            return False
        self._last = sent_ns
        return True

    def admit(self, source_ns: int) -> bool:
        if not self.enabled or not source_ns:
            return True
        if source_ns < self._last:
            return False
        self._last = source_ns
        return True


class Lifespan(Admission):
    """``msg_valid_period``: a message older than the subscriber's own ``valid`` seconds, or its publisher's
    ``msg_valid_period`` (the shorter applies), by its source stamp, is dropped. Cyclone expires samples in its
    cache, but a sample taken can still wait behind slow callbacks; a publisher whose QoS is unknown (TCPROS) has
    none. Active once either asks: the subscriber's own is finite, or a publisher that has one connected
    (:meth:`publisher`).

    >>> life = Lifespan(1.0)
    >>> life.check(0, time.time_ns() - 2_000_000_000, None), life.check(0, time.time_ns(), None)
    (False, True)
    """

    __slots__ = ("valid", "_publishers")
    rank = 30

    def __init__(self, valid: float) -> None:
        super().__init__()
        self.valid = valid
        self._publishers = False

    def active(self) -> bool:
        return self._publishers or math.isfinite(self.valid)

    def publisher(self, qos: Any) -> bool:
        """A publisher of ``qos`` connected: True when that makes this check active (it was not)."""
        if self._publishers or qos is None or not math.isfinite(qos.msg_valid_period):
            return False
        was, self._publishers = self.active(), True
        return not was

    def check(self, sent_ns: int, source_ns: int, qos: Any) -> bool:
        valid = self.valid if qos is None else min(self.valid, qos.msg_valid_period)
        return not (source_ns and is_expired(source_ns, time.time_ns(), valid))


class DeadlineMonitor:
    """Silence longer than ``deadline`` seconds is a miss, reported once per ``deadline`` of silence.

    ``poll(now)`` returns the silent time when a miss is due; ``delivered(now)`` records a message and
    returns how long the silence lasted if it had missed the deadline (for a "data resumed" report).

    >>> d = DeadlineMonitor(0.5, start=0.0)
    >>> d.poll(0.4), d.poll(0.6), d.poll(0.7), d.delivered(2.0)
    (None, 0.6, None, 2.0)
    """

    __slots__ = ("deadline", "_last_delivery", "_last_report", "_missing", "missed_total", "next_due")

    def __init__(self, deadline: float, *, start: float) -> None:
        self.deadline = deadline
        self._last_delivery = start
        self._last_report = start
        self._missing = False
        self.missed_total = 0
        #: the earliest time :meth:`poll` can report a miss (a caller may skip polling before it)
        self.next_due = start + deadline

    @property
    def enabled(self) -> bool:
        return math.isfinite(self.deadline)

    def poll(self, now: float) -> Optional[float]:
        if not self.enabled or now - self._last_report < self.deadline:
            return None
        self._last_report = now
        self.next_due = now + self.deadline
        self._missing = True
        self.missed_total += 1
        return now - self._last_delivery

    def delivered(self, now: float) -> Optional[float]:
        silent = now - self._last_delivery
        self._last_delivery = self._last_report = now
        self.next_due = now + self.deadline
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
