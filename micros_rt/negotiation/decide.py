"""What a publisher's decision on a subscriber's offer is made of: the :class:`PublicationFacts` it is judged
against, the :class:`Verdict` (accepted or not, and why in words) and the QoS check every transport makes.

Each transport decides in its own package (:func:`micros_rt.transports.dds.offer.decide`,
:func:`micros_rt.transports.shm.offer.decide_shm`): pure functions that, like
:func:`micros_rt.qos.check_compatibility` (which :func:`qos_mismatch` uses), create nothing and touch no network.
The negotiation adapter logs the reason of a declined offer and moves on to the subscriber's next protocol.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Optional

from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions, check_compatibility

__all__ = ["MAX_VERDICTS", "PublicationFacts", "Verdict", "qos_mismatch", "remember_verdict"]


@dataclass(frozen=True)
class PublicationFacts:
    """What a publication knows when an offer arrives."""

    topic: str               # resolved ROS name, e.g. /chatter
    dds_topic: str           # rt/chatter
    domain: Optional[int]    # None: DDS is unavailable in this process (or for this topic)
    type_name: str
    md5: str
    options: AdvertiseQoSOptions
    latch: bool
    pending: int = 0         # accepted offers whose reader discovery has not matched yet


@dataclass(frozen=True)
class Verdict:
    """``accepted`` or not; ``kind`` is a short stable key (for counting repeats), ``reason`` words."""

    accepted: bool
    kind: str
    reason: str
    #: an expected decline, logged at debug level only (SHM with a subscriber on another host)
    quiet: bool = False

    def __bool__(self) -> bool:
        return self.accepted


def qos_mismatch(requested: SubscribeQoSOptions, transient_local: bool, facts: PublicationFacts,
                 words: str) -> Optional[Verdict]:
    """The verdict on a subscriber's requested QoS against the publication's (None: compatible)."""
    verdict = check_compatibility(facts.options, requested, topic=facts.topic, offered_latch=facts.latch,
                                  requested_transient_local=transient_local)
    if verdict.compatible:
        return None
    return Verdict(False, f"qos:{verdict.option}", f"{words}: {verdict.reason}")


#: Verdicts remembered per publication (fake offers from many caller ids must not grow memory).
MAX_VERDICTS = 256


def remember_verdict(table: "collections.OrderedDict[str, Verdict]", subscriber: str, verdict: Verdict) -> None:
    """Keep ``verdict`` as the last one for ``subscriber`` in ``table`` (bounded: oldest forgotten first)."""
    table.pop(subscriber, None)
    table[subscriber] = verdict
    while len(table) > MAX_VERDICTS:
        table.popitem(last=False)
