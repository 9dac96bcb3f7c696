"""The TCPROS transport's reader: rospy's own Subscriber (registration, negotiation through :mod:`.patches`,
a receive thread per link) feeding a subscription's pushed reader."""

from __future__ import annotations

from typing import Any, Callable, Optional

from ...negotiation import DDS, TCPROS
from . import patches

__all__ = ["TcprosReader"]


class TcprosReader:
    """TCPROS for one subscription: the rospy Subscriber (registration, negotiation, receive threads)."""

    protocol = TCPROS

    def __init__(self, topic: str, data_class: Any, callback: Callable[[Any], None],
                 queue_size: Optional[int]) -> None:
        self._sub = patches.ROSPY_SUBSCRIBER(topic, data_class, callback, queue_size=queue_size)

    def transports(self) -> dict[str, str]:
        """Publisher URI -> 'DDS' or 'TCPROS' for every current connection."""
        impl = self._sub.impl
        if impl is None:
            return {}
        return {c.endpoint_id: getattr(c, "transport_type", TCPROS) for c in impl.connections}

    def unmatched_dds(self) -> set[str]:
        """Publisher URIs of DDS links whose writer this subscription's reader has not matched yet: DDS delivers a
        volatile reader only what its writer sends after the reader found it (on a lossy link, seconds later)."""
        impl = self._sub.impl
        if impl is None:
            return set()
        return {c.endpoint_id for c in impl.connections
                if getattr(c, "transport_type", TCPROS) == DDS and not getattr(c, "seen", True)}

    def close(self) -> None:
        self._sub.unregister()
