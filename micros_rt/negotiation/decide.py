"""The publisher's decision on a subscriber's DDS offer: a pure function with a verdict and a reason.

Like :func:`micros_rt.qos.check_compatibility` (which it uses), :func:`decide` creates nothing and
touches no network: the publication gathers :class:`PublicationFacts`, the negotiation adapter
logs the reason of a declined offer and moves on to the subscriber's next protocol.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Optional

from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions, check_compatibility
from .messages import DDSOffer, ShmOffer
from .protocol import MAX_PENDING_DDS_OFFERS

__all__ = ["PublicationFacts", "Verdict", "decide", "decide_shm"]


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


def _qos_mismatch(requested: SubscribeQoSOptions, transient_local: bool, facts: PublicationFacts,
                  words: str) -> Optional[Verdict]:
    """The verdict on a subscriber's requested QoS against the publication's (None: compatible)."""
    verdict = check_compatibility(facts.options, requested, topic=facts.topic, offered_latch=facts.latch,
                                  requested_transient_local=transient_local)
    if verdict.compatible:
        return None
    return Verdict(False, f"qos:{verdict.option}", f"{words}: {verdict.reason}")


def decide(offer: DDSOffer, facts: PublicationFacts, *, subscriber: str) -> Verdict:
    """Accept ``offer`` for DDS, or say why not (the subscriber then gets its next protocol).

    >>> facts = PublicationFacts("/chatter", "rt/chatter", 0, "std_msgs::msg::dds_::String_", "992c",
    ...                          AdvertiseQoSOptions(), latch=False)
    >>> decide(offer, facts, subscriber="/listener").kind                       # doctest: +SKIP
    'accepted'
    """
    topic = facts.topic
    if facts.domain is None:
        return Verdict(False, "dds-unavailable",
                       f"topic {topic}: subscriber {subscriber} asked for DDS but DDS is unavailable in this "
                       f"publisher process; using TCPROS")
    if offer.domain != facts.domain:
        return Verdict(False, "domain",
                       f"topic {topic}: subscriber {subscriber} is on DDS domain {offer.domain}, this publisher "
                       f"on {facts.domain}; set the same ROS_DOMAIN_ID on both to use DDS. Using TCPROS")
    if offer.md5 not in ("*", facts.md5):
        return Verdict(False, "md5",
                       f"topic {topic}: message type mismatch with {subscriber} (md5 {offer.md5} vs "
                       f"{facts.md5}); not using DDS")
    if offer.type_name != facts.type_name:
        return Verdict(False, "type",
                       f"topic {topic}: subscriber {subscriber} expects DDS type {offer.type_name}, this "
                       f"publisher writes {facts.type_name}; not using DDS")
    if offer.topic != facts.dds_topic:
        return Verdict(False, "topic",
                       f"topic {topic}: subscriber {subscriber} offered DDS topic {offer.topic}, this publisher "
                       f"writes {facts.dds_topic}; not using DDS")
    mismatch = _qos_mismatch(offer.qos, offer.transient_local, facts,
                             f"DDS QoS mismatch with subscriber {subscriber}, falling back to TCPROS")
    if mismatch is not None:
        return mismatch
    if facts.pending >= MAX_PENDING_DDS_OFFERS:
        return Verdict(False, "pending-limit",
                       f"topic {topic}: {facts.pending} DDS subscribers accepted but not yet discovered (limit "
                       f"{MAX_PENDING_DDS_OFFERS}); serving {subscriber} over TCPROS")
    return Verdict(True, "accepted", f"topic {topic}: DDS accepted for subscriber {subscriber}")


def decide_shm(offer: ShmOffer, facts: PublicationFacts, *, host: str, unavailable: Optional[str],
               subscriber: str) -> Verdict:
    """Accept ``offer`` for shared memory, or say why not. ``host`` is this publisher's host identity
    (:func:`micros_rt.transports.shm.host_identity`), ``unavailable`` why shared memory cannot be used in
    this process (None: it can).

    >>> facts = PublicationFacts("/chatter", "", None, "", "992c", AdvertiseQoSOptions(), latch=False)
    >>> offer = ShmOffer("boot/net/mnt/1000", "992c", "std_msgs/String", SubscribeQoSOptions())
    >>> decide_shm(offer, facts, host="boot/net/mnt/1000", unavailable=None, subscriber="/l").kind
    'accepted'
    >>> decide_shm(offer, facts, host="other/net/mnt/1000", unavailable=None, subscriber="/l").quiet
    True
    """
    topic = facts.topic
    if offer.host != host:
        # a subscriber on another machine or network namespace is the normal case: no warning
        same_machine = offer.host.split("/")[:3] == host.split("/")[:3]
        same_user = same_machine and offer.host.split("/")[3:4] == host.split("/")[3:4]
        why = ("keeps its shared memory elsewhere (another micros_rt version: its iceoryx2 directory is not this "
               "one's)" if same_user else
               "runs as another Unix user (processes of different users cannot share iceoryx2 memory)"
               if same_machine else "is on another host")
        return Verdict(False, "shm-host", f"topic {topic}: subscriber {subscriber} {why}; not using shared memory",
                       quiet=not same_machine)
    if unavailable is not None:
        return Verdict(False, "shm-unavailable", f"topic {topic}: subscriber {subscriber} asked for shared memory "
                                                 f"but this publisher cannot use it: {unavailable}")
    if offer.md5 not in ("*", facts.md5):
        return Verdict(False, "md5", f"topic {topic}: message type mismatch with {subscriber} (md5 {offer.md5} vs "
                                     f"{facts.md5}); not using shared memory")
    mismatch = _qos_mismatch(offer.qos, offer.transient_local, facts,
                             f"QoS mismatch with subscriber {subscriber}, not using shared memory")
    if mismatch is not None:
        return mismatch
    return Verdict(True, "accepted", f"topic {topic}: shared memory accepted for subscriber {subscriber}")


#: Verdicts remembered per publication (fake offers from many caller ids must not grow memory).
MAX_VERDICTS = 256


def remember_verdict(table: "collections.OrderedDict[str, Verdict]", subscriber: str, verdict: Verdict) -> None:
    """Keep ``verdict`` as the last one for ``subscriber`` in ``table`` (bounded: oldest forgotten first)."""
    table.pop(subscriber, None)
    table[subscriber] = verdict
    while len(table) > MAX_VERDICTS:
        table.popitem(last=False)
