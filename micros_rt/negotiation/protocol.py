"""The one set of protocol names and negotiation limits, shared by both sides of ``requestTopic``."""

from __future__ import annotations

import re
from typing import List, Tuple

__all__ = [
    "DDS",
    "SHM",
    "TCPROS",
    "DEFAULT_PROTOCOLS",
    "NEGOTIATED_PROTOCOLS",
    "negotiated_protocols",
    "register_protocol",
    "unregister_protocol",
    "MAX_FIELD_CHARS",
]

DDS = "DDS"
#: Shared memory (iceoryx2) between two micros_rt processes of one host and user.
SHM = "SHM"
TCPROS = "TCPROS"
#: Shared memory first (declined by a publisher on another host, in a few microseconds), then DDS, then TCPROS.
DEFAULT_PROTOCOLS: Tuple[str, ...] = (SHM, DDS, TCPROS)
#: Protocols negotiated by micros_rt itself in ``requestTopic`` (a stock node skips their entries).
NEGOTIATED_PROTOCOLS: Tuple[str, ...] = (SHM, DDS)
_negotiated: List[str] = list(NEGOTIATED_PROTOCOLS)
_NAME = re.compile(r"^[A-Z][A-Z0-9_]{1,31}$")


def negotiated_protocols() -> Tuple[str, ...]:
    """The built-in negotiated protocols and those a program registered (:func:`register_protocol`)."""
    return tuple(_negotiated)


def register_protocol(name: str) -> None:
    """Know ``name`` as a negotiated protocol (TransportHints and profiles accept it); ValueError in words for
    a name that is not upper case letters, digits and ``_``, or one of ROS 1's own."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"a negotiated protocol's name is 2-32 upper case letters, digits or '_', got {name!r}")
    if name in (TCPROS, "UDPROS"):
        raise ValueError(f"{name} is ROS 1's own protocol, not one micros_rt negotiates")
    if name not in _negotiated:
        _negotiated.append(name)


def unregister_protocol(name: str) -> None:
    """Forget a name :func:`register_protocol` added (a built-in one stays)."""
    if name in _negotiated and name not in NEGOTIATED_PROTOCOLS:
        _negotiated.remove(name)


#: Longest string accepted in any field of an offer or answer (names, GUIDs, graph ids, md5).
MAX_FIELD_CHARS = 256
