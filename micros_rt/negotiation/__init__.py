"""Protocol negotiation: TransportHints, the typed DDS offer/answer, the publisher's decision and the
protocol-order loop. Pure: nothing here touches rospy or creates DDS entities
(:mod:`micros_rt.transports.tcpros.patches` adapts it to rospy's ``requestTopic``)."""

from .choose import Choice, OfferJudge, choose_protocol, dds_transport
from .decide import MAX_VERDICTS, PublicationFacts, Verdict, decide, decide_shm, remember_verdict
from .hints import TransportHints
from .messages import DDSAnswer, DDSOffer, DDSOpenFirst, MalformedNegotiationError, ShmAnswer, ShmOffer, is_guid
from .protocol import (
    DDS,
    DEFAULT_PROTOCOLS,
    NEGOTIATED_PROTOCOLS,
    SHM,
    MAX_FIELD_CHARS,
    MAX_PENDING_DDS_OFFERS,
    TCPROS,
    UNMATCHED_READER_TIMEOUT,
)
from ..ratelimit import RateLimitedLog

__all__ = [
    "DDS",
    "DEFAULT_PROTOCOLS",
    "NEGOTIATED_PROTOCOLS",
    "SHM",
    "ShmAnswer",
    "ShmOffer",
    "decide_shm",
    "MAX_FIELD_CHARS",
    "MAX_PENDING_DDS_OFFERS",
    "MAX_VERDICTS",
    "TCPROS",
    "UNMATCHED_READER_TIMEOUT",
    "Choice",
    "DDSAnswer",
    "DDSOffer",
    "DDSOpenFirst",
    "MalformedNegotiationError",
    "OfferJudge",
    "PublicationFacts",
    "RateLimitedLog",
    "TransportHints",
    "Verdict",
    "choose_protocol",
    "decide",
    "dds_transport",
    "is_guid",
    "remember_verdict",
]
