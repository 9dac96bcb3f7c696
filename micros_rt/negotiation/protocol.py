"""The one set of protocol names and negotiation limits, shared by both sides of ``requestTopic``."""

from __future__ import annotations

from typing import Tuple

__all__ = [
    "DDS",
    "SHM",
    "TCPROS",
    "DEFAULT_PROTOCOLS",
    "NEGOTIATED_PROTOCOLS",
    "MAX_FIELD_CHARS",
    "MAX_PENDING_DDS_OFFERS",
    "UNMATCHED_READER_TIMEOUT",
]

DDS = "DDS"
#: Shared memory (iceoryx2) between two micros_rt processes of one host and user.
SHM = "SHM"
TCPROS = "TCPROS"
#: Shared memory first (declined by a publisher on another host, in a few microseconds), then DDS, then TCPROS.
DEFAULT_PROTOCOLS: Tuple[str, ...] = (SHM, DDS, TCPROS)
#: Protocols negotiated by micros_rt itself in ``requestTopic`` (a stock node skips their entries).
NEGOTIATED_PROTOCOLS: Tuple[str, ...] = (SHM, DDS)

#: Longest string accepted in any field of a DDS offer or answer (names, GUIDs, graph ids, md5).
MAX_FIELD_CHARS = 256
#: Accepted DDS offers whose reader DDS discovery has not matched yet, per publication. More are
#: declined (the subscriber falls back to TCPROS): a flood of fake offers must not grow the node.
MAX_PENDING_DDS_OFFERS = 64
#: Seconds an accepted DDS offer may wait for discovery to match its reader before it is dropped.
UNMATCHED_READER_TIMEOUT = 5.0
