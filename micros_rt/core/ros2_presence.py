"""What this node tells its host's ROS 2 gateway (``auto`` visibility, :mod:`micros_rt.transports.dds.host_gateway`):
each endpoint that would be a ROS 2 endpoint (it has a DDS side the node's profile does not refuse), with its type,
queue, latch, QoS options and tag, so that the gateway announces it to ROS 2's graph as this node's."""

from __future__ import annotations

from typing import TYPE_CHECKING, List, Sequence, Tuple

from ..negotiation.protocol import DDS
from ..transports.dds.host_gateway import EndpointDescription

if TYPE_CHECKING:
    from .publication import _Publication
    from .subscription import _Subscription

__all__ = ["endpoint_descriptions"]


_last: Tuple[Tuple[int, ...], List[EndpointDescription]] = ((), [])


def endpoint_descriptions(pubs: Sequence["_Publication"], subs: Sequence["_Subscription"]
                          ) -> List[EndpointDescription]:
    """This node's publications and subscriptions as the gateway reads them, in a stable order (made again only
    when the node's endpoints changed: this runs on every housekeeping tick)."""
    global _last
    key = (*(id(p) for p in pubs), *(id(s) for s in subs), *(int(p.closed) for p in pubs),
           *(int(s.closed) for s in subs))
    if key == _last[0]:
        return _last[1]
    out: List[EndpointDescription] = []
    for pub in pubs:
        side = pub.sides.get(DDS)
        if side is None or side.refusal is not None or pub.closed:
            continue
        cls = pub.data_class
        out.append(EndpointDescription("pub", pub.topic, cls._type, cls._md5sum, str(getattr(cls, "_full_text", "")),
                                       pub.queue_size, bool(pub.latch), pub.options.to_dict(), dict(pub.tag)))
    for sub in subs:
        if sub.sides.get(DDS) is None or sub.closed:
            continue
        cls = sub.data_class
        out.append(EndpointDescription("sub", sub.topic, cls._type, cls._md5sum, str(getattr(cls, "_full_text", "")),
                                       sub.queue_size, False, None if sub.options is None else sub.options.to_dict(),
                                       dict(sub.tag)))
    out.sort(key=lambda e: (e.kind, e.topic))
    _last = (key, out)
    return out
