"""The negotiated transports a node offers, in preference order: each a protocol name and the two makers of its
sides (:class:`micros_rt.transports.negotiated.NegotiatedTransport`), one for a publication and one for a
subscription.

The node registers the built-in ones (shared memory, DDS: :mod:`micros_rt.transports.builtin`) first; a program
adds its own with :func:`register` (the contract tests' toy transport does), and subscribers choose it by name in
their TransportHints (``TransportHints.from_names([...])``) or in a profile's ``transport_hints``. This module
names no transport.
"""

from __future__ import annotations

from typing import Dict, Tuple

from ..negotiation.protocol import NEGOTIATED_PROTOCOLS, register_protocol, unregister_protocol
from ..transports.negotiated import NegotiatedTransport

__all__ = ["NegotiatedTransport", "TRANSPORTS", "install_builtin", "register", "unregister"]

#: protocol name -> transport, in preference order (a publication's sides are made in this order)
TRANSPORTS: Dict[str, NegotiatedTransport] = {}


def install_builtin(transports: Tuple[NegotiatedTransport, ...]) -> None:
    """The node's own transports, first in the order (before any a program registered)."""
    plugged = {p: t for p, t in TRANSPORTS.items() if p not in NEGOTIATED_PROTOCOLS}
    TRANSPORTS.clear()
    TRANSPORTS.update({t.protocol: t for t in transports})
    TRANSPORTS.update(plugged)


def register(transport: NegotiatedTransport) -> None:
    """Offer ``transport`` on the topics advertised and subscribed from now on (after the built-in ones)."""
    register_protocol(transport.protocol)
    TRANSPORTS[transport.protocol] = transport


def unregister(protocol: str) -> None:
    """Stop offering a transport :func:`register` added (endpoints made meanwhile keep their sides); its name is no
    longer a protocol TransportHints and profiles accept."""
    if protocol in NEGOTIATED_PROTOCOLS:
        raise ValueError(f"{protocol} is built in; TransportHints and profiles choose whether it is used")
    TRANSPORTS.pop(protocol, None)
    unregister_protocol(protocol)
