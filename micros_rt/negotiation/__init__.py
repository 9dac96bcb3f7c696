"""Protocol negotiation, generic: TransportHints, the protocol names, the offer/answer error and field readers,
the verdict, the judge interface and the protocol-order loop. Each transport's offer, answer and decision live in
its own package (:mod:`micros_rt.transports.dds.offer`, :mod:`micros_rt.transports.shm.offer`). Pure: nothing
here touches rospy or creates DDS entities (:mod:`micros_rt.transports.tcpros.patches` adapts it to rospy's
``requestTopic``)."""

from .choose import Choice, OfferJudge, choose_protocol
from .decide import MAX_VERDICTS, PublicationFacts, Verdict, qos_mismatch, remember_verdict
from .hints import TransportHints
from .messages import INT32, MalformedNegotiationError, read_bool, read_qos, read_str, read_struct, short
from .protocol import (
    DDS,
    DEFAULT_PROTOCOLS,
    NEGOTIATED_PROTOCOLS,
    SHM,
    MAX_FIELD_CHARS,
    TCPROS,
)
from ..ratelimit import RateLimitedLog

__all__ = [
    "DDS",
    "DEFAULT_PROTOCOLS",
    "INT32",
    "NEGOTIATED_PROTOCOLS",
    "SHM",
    "MAX_FIELD_CHARS",
    "MAX_VERDICTS",
    "TCPROS",
    "Choice",
    "MalformedNegotiationError",
    "OfferJudge",
    "PublicationFacts",
    "RateLimitedLog",
    "TransportHints",
    "Verdict",
    "choose_protocol",
    "qos_mismatch",
    "read_bool",
    "read_qos",
    "read_str",
    "read_struct",
    "remember_verdict",
    "short",
]
