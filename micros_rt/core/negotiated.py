"""The negotiated transports a node offers, in preference order: each a protocol name and the two makers of its
sides (:mod:`micros_rt.transports.negotiated`), one for a publication and one for a subscription.

Shared memory and DDS are registered here; a program adds its own with :func:`register` (the contract tests'
toy transport does), and subscribers choose it by name in their TransportHints
(``TransportHints.from_names([...])``) or in a profile's ``transport_hints``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Callable, Dict, Optional

from ..negotiation import Verdict
from ..negotiation.protocol import DDS, SHM, register_protocol
from ..transports.dds.publication import DDSPublication
from ..transports.dds.subscription import DDSSubscription
from ..transports.negotiated import PublicationSide, SubscriptionSide
from ..transports.shm.publication import ShmPublication
from ..transports.shm.subscription import ShmSubscription
from .runtime import _log, _node, dds_backend, ros2_visible

if TYPE_CHECKING:
    from .publication import _Publication
    from .subscription import _Subscription

__all__ = ["NegotiatedTransport", "TRANSPORTS", "open_dds_sides", "register", "unregister"]


@dataclasses.dataclass(frozen=True)
class NegotiatedTransport:
    """A negotiated transport as a node uses it."""

    protocol: str
    #: ``(publication, refusal) -> side``; ``refusal``: the node's profile keeps the topic off this transport
    #: (a verdict in words), else None
    publication: Callable[["_Publication", Optional[Verdict]], PublicationSide]
    #: ``(subscription) -> side``, made when the subscription's TransportHints allow the protocol
    subscription: Callable[["_Subscription"], SubscriptionSide]


def _dds_publication(pub: "_Publication", refusal: Optional[Verdict]) -> PublicationSide:
    # with ROS 2 visibility off, the DDS writer comes with the first subscriber that takes DDS
    eager = ros2_visible(_node.profile)
    return DDSPublication(pub, backend=dds_backend() if eager and refusal is None else None, tag=pub.tag,
                          lazy=None if eager or refusal is not None else dds_backend, refusal=refusal)


def _dds_subscription(sub: "_Subscription") -> SubscriptionSide:
    # with ROS 2 visibility off, the DDS reader comes with the first publisher that takes DDS
    eager = ros2_visible(_node.profile)
    return DDSSubscription(sub, backend=sub.dds, lazy=None if eager else dds_backend)


def open_dds_sides() -> None:
    """ROS 2 was seen (``auto`` visibility): every topic's DDS writer and reader now, as visibility on makes them
    with the topic; the links negotiated before stay as they are."""
    opened = 0
    for pub in _node.publications.all():
        writer = pub.sides.get(DDS)
        if isinstance(writer, DDSPublication) and writer.ensure_writer():
            opened += 1
    for sub in _node.subscriptions.all():
        reader = sub.sides.get(DDS)
        if isinstance(reader, DDSSubscription) and reader.open_first():
            opened += 1
    _log.info("micros_rt: ROS 2 is on the DDS domain: this node's topics are ROS 2 topics now (%d DDS writers and "
              "readers)", opened)


#: protocol name -> transport, in preference order (a publication's sides are made in this order)
TRANSPORTS: Dict[str, NegotiatedTransport] = {
    SHM: NegotiatedTransport(SHM, lambda pub, refusal: ShmPublication(pub, refusal=refusal),
                             lambda sub: ShmSubscription(sub, poll=sub.poll_link)),
    DDS: NegotiatedTransport(DDS, _dds_publication, _dds_subscription),
}


def register(transport: NegotiatedTransport) -> None:
    """Offer ``transport`` on the topics advertised and subscribed from now on (after the built-in ones)."""
    register_protocol(transport.protocol)
    TRANSPORTS[transport.protocol] = transport


def unregister(protocol: str) -> None:
    """Stop offering a transport :func:`register` added (endpoints made meanwhile keep their sides)."""
    if protocol in (SHM, DDS):
        raise ValueError(f"{protocol} is built in; TransportHints and profiles choose whether it is used")
    TRANSPORTS.pop(protocol, None)
