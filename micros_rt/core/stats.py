"""Counters and latency statistics of publishers and subscribers (what ``statistics()`` returns)."""

from __future__ import annotations

import collections
import math
import dataclasses
from dataclasses import dataclass
from typing import Any, Deque, Dict, Mapping, Tuple

__all__ = ["LatencyStats", "SubscriberStatistics", "PublisherStatistics"]


@dataclass(frozen=True)
class SubscriberStatistics:
    """A snapshot of one subscription's counters (all transports).

    ``received`` counts messages handed to the subscription; ``delivered`` those its callbacks got.
    Every message not delivered is in exactly one drop counter: ``dropped_queue_full`` (the newest
    ``queue_size`` are kept, as in ROS), ``dropped_expired`` (older than the publisher's
    msg_valid_period), ``dropped_filtered`` (time_filter_duration), ``dropped_out_of_order`` (stamped
    before the last one delivered, ordered_by_sending_timestamp), ``malformed`` (undecodable DDS samples).
    ``writers``: DDS writers this subscription keeps state for right now. The enforced options' counters are the
    QoS catalogue's (:func:`micros_rt.qos.options.drop_counters`); one this class has no field for (an option added
    since) is in ``extra`` and read as an attribute all the same.
    """

    received: int
    delivered: int
    dropped_queue_full: int
    dropped_expired: int
    dropped_filtered: int
    malformed: int
    deadline_missed: int
    writers: int
    dropped_out_of_order: int = 0
    #: (counter, count) of the catalogue's counters that have no field here
    extra: Tuple[Tuple[str, int], ...] = ()

    @classmethod
    def of(cls, counters: Mapping[str, int], **fields: Any) -> "SubscriberStatistics":
        """``fields`` and the enforcers' ``counters`` (by the catalogue's names), those without a field in
        :attr:`extra`."""
        known = _FIELDS.intersection(counters)
        return cls(**fields, **{k: counters[k] for k in known},
                   extra=tuple((k, v) for k, v in counters.items() if k not in known))

    def __getattr__(self, name: str) -> int:
        for key, value in self.__dict__.get("extra", ()):
            if key == name:
                return int(value)
        raise AttributeError(f"SubscriberStatistics has no counter {name!r}")


@dataclass(frozen=True)
class PublisherStatistics:
    """A snapshot of one publication's counters: messages published, dropped before they left (KEEP_LAST
    samples superseded while the link had no room, and those out of date: ``expired``, older than their
    lifespan or a best-effort topic's latency budget; a best-effort or KEEP_LAST DDS link can still lose
    messages downstream, counted by the subscriber), and the seconds ``publish()`` spent blocked on
    back-pressure (``queue_size=None``)."""

    published: int
    dropped: int
    blocked_seconds: float
    expired: int = 0
    #: negotiation offers refused although their protocol's rules matched (a forged or unconfirmed caller, a live
    #: link of the caller the offer does not name, too many links waiting), and links made for an offer that its
    #: subscriber never took up (closed after a bound): what a flood of forged offers cost, counted
    refused_offers: int = 0
    unused_links: int = 0


_FIELDS = frozenset(f.name for f in dataclasses.fields(SubscriberStatistics)) - {"extra"}


class LatencyStats:
    """Source stamp to callback latency of one subscription (seconds).

    Measured from the publisher's source timestamp (DDS) or Header stamp (TCPROS, stamped messages
    only) to the callback, waiting behind earlier callbacks included. ``count``, ``mean``, ``max``
    cover every message; ``p50``/``p99`` the last ``keep``. ``budget_misses`` counts messages later
    than their publisher's ``latency_budget`` (publishers that declare one: micros_rt over DDS).
    """

    def __init__(self, keep: int = 4096) -> None:
        self.samples: Deque[float] = collections.deque(maxlen=keep)
        self.count = 0
        self.total = 0.0
        self.max = -math.inf  # a writer whose clock runs ahead gives negative latencies
        self.budget_checked = 0
        self.budget_misses = 0

    def add(self, latency: float, budget: float = 0.0) -> bool:
        """Record one latency; True when it missed ``budget`` (> 0)."""
        self.samples.append(latency)
        self.count += 1
        self.total += latency
        if latency > self.max:
            self.max = latency
        if budget > 0.0:
            self.budget_checked += 1
            if latency > budget:
                self.budget_misses += 1
                return True
        return False

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100, nearest rank) of the recent latencies; NaN when empty."""
        return _nearest_rank(sorted(self.samples), q)

    @property
    def p50(self) -> float:
        return self.percentile(50)

    @property
    def p99(self) -> float:
        return self.percentile(99)

    def summary(self) -> Dict[str, float]:
        """count, mean, p50, p99, max (seconds), budget_checked and budget_misses, as a dict."""
        data = sorted(self.samples)
        return {"count": self.count, "mean": self.mean, "p50": _nearest_rank(data, 50),
                "p99": _nearest_rank(data, 99), "max": self.max if self.count else math.nan,
                "budget_checked": self.budget_checked, "budget_misses": self.budget_misses}


def _nearest_rank(data: "list[float]", q: float) -> float:
    if not data:
        return math.nan
    return data[min(max(1, math.ceil(q / 100.0 * len(data))), len(data)) - 1]
