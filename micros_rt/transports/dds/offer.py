"""DDS's offer (subscriber -> publisher) and answer (publisher -> subscriber) of ``requestTopic``, and the
publisher's decision on an offer (:func:`decide`, a pure function with a verdict and a reason).

Both sides build and read these values only through :meth:`~DDSOffer.to_xmlrpc` / ``from_xmlrpc``, so the keys
one side writes are the keys the other reads; ``from_xmlrpc`` validates everything a remote node sends (types,
lengths, GUID format) and raises :class:`~micros_rt.negotiation.MalformedNegotiationError` naming the field.

>>> offer = DDSOffer(domain=0, topic="rt/chatter", type_name="std_msgs::msg::dds_::String_",
...                  md5="992ce8a1687cec8c8bd883ec73ca41d1", qos=SubscribeQoSOptions(),
...                  reader="01106fda-d45a-29f3-b1ee-b181000001c1",
...                  participant="01106fda-d45a-29f3-b1ee-b181000001c1", graph="run@uri")
>>> DDSOffer.from_xmlrpc(offer.to_xmlrpc()[1]) == offer
True
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Tuple

from ...negotiation import (DDS, INT32, MalformedNegotiationError, OfferJudge, PublicationFacts, Verdict, qos_mismatch, read_bool, read_qos, read_str, read_struct,
                            short)
from ...qos import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = ["MAX_PENDING_DDS_OFFERS", "UNMATCHED_READER_TIMEOUT", "DDSAnswer", "DDSOffer", "DDSOpenFirst", "decide",
           "dds_transport", "is_guid"]

#: Accepted DDS offers whose reader DDS discovery has not matched yet, per publication. More are
#: declined (the subscriber falls back to TCPROS): a flood of fake offers must not grow the node.
MAX_PENDING_DDS_OFFERS = 64
#: Seconds an accepted DDS offer may wait for discovery to match its reader before it is dropped.
UNMATCHED_READER_TIMEOUT = 5.0

_GUID = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")
#: a resolved (global) ROS name as rosgraph.names.is_legal_name accepts them, without a trailing slash
_ROS_NAME = re.compile(r"^(/[A-Za-z0-9_]+)+$")


def is_guid(value: object) -> bool:
    """True for Cyclone's textual GUID form (``01106fda-d45a-29f3-b1ee-b181000001c1``)."""
    return isinstance(value, str) and bool(_GUID.fullmatch(value))


def _guid(d: Mapping[str, Any], key: str) -> str:
    value = read_str(d, key)
    if not is_guid(value):
        raise MalformedNegotiationError(key, f"{short(value)} is not a DDS GUID")
    return value


def _topic_name(d: Mapping[str, Any], key: str) -> str:
    """An optional resolved ROS topic name (``/robot_a/chatter``): what a subscriber may open a reader on."""
    value = read_str(d, key, required=False)
    if value and not _ROS_NAME.fullmatch(value):
        raise MalformedNegotiationError(key, f"{short(value)} is not a resolved ROS topic name")
    return value


@dataclass(frozen=True)
class DDSOffer:
    """What a micros_rt subscriber offers in its ``['DDS', {...}]`` protocol entry."""

    domain: int
    topic: str
    type_name: str
    md5: str
    qos: SubscribeQoSOptions
    reader: str
    participant: str
    graph: str
    #: The subscriber wants the latched message (a transient-local reader).
    transient_local: bool = False
    #: The subscriber opens a reader on another DDS topic when an answer names one (``DDSAnswer.topic``).
    follow: bool = False
    #: The subscriber has no DDS reader yet (it makes DDS entities only when a peer needs them): a publisher
    #: that would take DDS answers :class:`DDSOpenFirst`, and the subscriber opens its reader and asks again.
    #: ``topic``, ``type_name``, ``reader`` and ``participant`` are empty then.
    lazy: bool = False

    def to_xmlrpc(self) -> List[Any]:
        """The protocol entry, ``['DDS', {...}]`` (roscpp needs every entry to be a list)."""
        if self.lazy:
            return [DDS, {"lazy": True, "domain": self.domain, "md5": self.md5, "qos": self.qos.to_dict(),
                          "graph": self.graph}]
        return [DDS, {
            "domain": self.domain, "topic": self.topic, "type": self.type_name, "md5": self.md5,
            "qos": self.qos.to_dict(), "reader": self.reader, "participant": self.participant,
            "graph": self.graph, "transient_local": self.transient_local, "follow": self.follow,
        }]

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a subscriber") -> "DDSOffer":
        d = read_struct(params, "DDS offer")
        domain = d.get("domain")
        if isinstance(domain, bool) or not isinstance(domain, int) or not INT32[0] <= domain <= INT32[1]:
            raise MalformedNegotiationError("domain", f"expected an integer DDS domain id, got {short(domain)}")
        qos = read_qos(SubscribeQoSOptions, d, source)
        if read_bool(d, "lazy"):
            return cls(domain=domain, topic="", type_name="", md5=read_str(d, "md5"), qos=qos, reader="",
                       participant="", graph=read_str(d, "graph"), lazy=True)
        return cls(domain=domain, topic=read_str(d, "topic"), type_name=read_str(d, "type"),
                   md5=read_str(d, "md5"), qos=qos, reader=_guid(d, "reader"),
                   participant=_guid(d, "participant"), graph=read_str(d, "graph"),
                   transient_local=read_bool(d, "transient_local"), follow=read_bool(d, "follow"))


@dataclass(frozen=True)
class DDSOpenFirst:
    """A publisher's answer to a lazy DDS offer (:attr:`DDSOffer.lazy`): it would take DDS; the subscriber opens
    its DDS reader and asks again with a full offer. ``['DDS', {'open_first': True}]``."""

    def to_xmlrpc(self) -> List[Any]:
        return [DDS, {"open_first": True}]

    @staticmethod
    def is_one(entry: object) -> bool:
        return (isinstance(entry, list) and len(entry) == 2 and entry[0] == DDS and isinstance(entry[1], dict)
                and entry[1].get("open_first") is True)


@dataclass(frozen=True)
class DDSAnswer:
    """What a micros_rt publisher answers when it accepts DDS: ``['DDS', {...}]``."""

    writer: str
    participant: str
    latch: bool
    qos: AdvertiseQoSOptions
    node: str = ""
    #: Not empty: the publisher republishes another graph's topic that reaches this domain already, and
    #: serves its DDS subscribers with the writers of that graph's relay (tag ``relay=<via>``), not its own
    #: (``writer`` is one of them): no second hop through the publisher's process.
    via: str = ""
    #: With ``via``: the ROS name of the topic those writers write when it is not the subscriber's own (an
    #: import renamed by the relay); the subscriber reads it with a reader of its own (``DDSOffer.follow``).
    topic: str = ""

    def to_xmlrpc(self) -> List[Any]:
        return [DDS, self.params()]

    def params(self) -> Dict[str, Any]:
        params = {"writer": self.writer, "participant": self.participant, "latch": self.latch,
                  "qos": self.qos.to_dict(), "node": self.node}
        if self.via:
            params["via"] = self.via
        if self.topic:
            params["topic"] = self.topic
        return params

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a publisher") -> "DDSAnswer":
        d = read_struct(params, "DDS answer")
        qos = read_qos(AdvertiseQoSOptions, d, source)
        return cls(writer=_guid(d, "writer"), participant=_guid(d, "participant"),
                   latch=read_bool(d, "latch"), qos=qos, node=read_str(d, "node", required=False),
                   via=read_str(d, "via", required=False), topic=_topic_name(d, "topic"))


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
    mismatch = qos_mismatch(offer.qos, offer.transient_local, facts,
                             f"DDS QoS mismatch with subscriber {subscriber}, falling back to TCPROS")
    if mismatch is not None:
        return mismatch
    if facts.pending >= MAX_PENDING_DDS_OFFERS:
        return Verdict(False, "pending-limit",
                       f"topic {topic}: {facts.pending} DDS subscribers accepted but not yet discovered (limit "
                       f"{MAX_PENDING_DDS_OFFERS}); serving {subscriber} over TCPROS")
    return Verdict(True, "accepted", f"topic {topic}: DDS accepted for subscriber {subscriber}")


#: Judges one offer: (verdict, answer when accepted: a DDSAnswer, or DDSOpenFirst for a lazy offer).
JudgeDDS = Callable[[DDSOffer], Tuple[Verdict, Any]]


def dds_transport(judge: JudgeDDS) -> OfferJudge:
    """DDS as a negotiated transport, judged by ``judge`` (a publication's)."""
    return OfferJudge(parse=lambda params, source: DDSOffer.from_xmlrpc(params, source=source), judge=judge)
