"""The negotiated transports every node offers, in preference order: shared memory, then DDS (each its two sides,
:mod:`micros_rt.transports.negotiated`). The node (:mod:`micros_rt.node`) registers them in the core's registry
(:mod:`micros_rt.core.negotiated`), before any a program registers, and gives DDS the process's back end."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Optional, Tuple, cast

from ..negotiation import DDS, SHM, Verdict
from .dds.publication import DDSPublication
from .dds.subscription import DDSSubscription, DDSSubscriptionHost
from .base import Inbox
from .negotiated import NegotiatedTransport, PublicationHost, PublicationSide, SubscriptionHost, SubscriptionSide
from .shm.host import unavailable_reason as shm_unavailable
from .shm.inbox import ShmInbox
from .shm.publication import ShmPublication
from .shm.subscription import ShmSubscription

if TYPE_CHECKING:
    from .dds.backend import DDSBackend

__all__ = ["builtin_transports", "inbox_for"]


def builtin_transports(*, dds_backend: "Callable[[], Optional[DDSBackend]]",
                       visible: Callable[[], bool]) -> Tuple[NegotiatedTransport, ...]:
    """Shared memory and DDS. ``dds_backend()``: the process's DDS back end (None: DDS cannot start);
    ``visible()``: whether the node's topics are ROS 2 topics now (DDS writers and readers with each topic; else
    they come with the first peer that takes DDS)."""

    def dds_publication(host: PublicationHost, refusal: Optional[Verdict]) -> PublicationSide:
        eager = visible()
        return DDSPublication(host, backend=dds_backend() if eager and refusal is None else None, tag=host.tag,
                              lazy=None if eager or refusal is not None else dds_backend, refusal=refusal)

    def dds_subscription(host: SubscriptionHost) -> SubscriptionSide:
        # the subscription is the DDS side's host too (its exactly-once table, its pulled readers)
        eager = visible()
        return DDSSubscription(cast(DDSSubscriptionHost, host), backend=dds_backend() if eager else None,
                               lazy=None if eager else dds_backend)

    return (NegotiatedTransport(SHM, lambda host, refusal: ShmPublication(host, refusal=refusal),
                                lambda host: ShmSubscription(host, poll=host.poll_link)),
            NegotiatedTransport(DDS, dds_publication, dds_subscription))


def inbox_for(*, dds: "Optional[DDSBackend]", allows_shm: bool) -> Inbox:
    """What a subscription's delivery thread waits on. With shared memory, an iceoryx2 wait set on its SHM links'
    listeners (one thread wake per message), and DDS readers wake it per sample from Cyclone's thread; else, with
    a DDS reader from the start, Cyclone's wait set; else an Event until a first SHM link comes."""
    if dds is not None and not (allows_shm and shm_unavailable() is None):
        from .dds.inbox import CycloneInbox

        return CycloneInbox(dds.participant)
    return ShmInbox()
