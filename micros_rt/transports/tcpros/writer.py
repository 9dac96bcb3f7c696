"""The TCPROS transport's writer: rospy's own Publisher (master registration, TCPROS links to stock and
TCPROS-preferring subscribers) behind the transport writer methods; it marks and paces its links."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Optional

import genpy
import rospy

from ...exceptions import TransportError
from ...log import nonblocking_logger
from ...negotiation import TCPROS
from ...qos import TransportPriority, priority_tos
from ..marking import mark_socket
from . import patches

if TYPE_CHECKING:
    from ..pacing import LinkPacer

__all__ = ["TcprosWriter"]

_log = nonblocking_logger("rosout.micros_rt")


class TcprosWriter:
    """TCPROS, rospy's own transport, for one publication: the rospy Publisher (master registration too)
    behind the transport writer methods (:class:`micros_rt.transports.base.TransportWriter`).

    rospy serializes inside ``publish`` and raises ``genpy.SerializationError`` before writing anything,
    so :meth:`prepare` hands the message through and a publication sends TCPROS first. rospy's list of
    connections also holds micros_rt's DDS and SHM pseudo-connections (``pseudo_links()`` counts them): with no
    TCPROS link left and no latch, there is nothing to send."""

    protocol = TCPROS

    def __init__(self, topic: str, data_class: Any, queue_size: Optional[int], latch: bool, *,
                 pseudo_links: Callable[[], int], priority: TransportPriority = TransportPriority.NORMAL,
                 pacer: "Optional[LinkPacer]" = None) -> None:
        self.latch = latch
        self._pub = patches.ROSPY_PUBLISHER(topic, data_class, queue_size=queue_size, latch=latch)
        self._impl = self._pub.impl
        self._pseudo_links = pseudo_links
        self.guid = topic
        self.priority = priority
        self._pacer = pacer

    def link_opened(self, conn: Any, sock: Any) -> None:
        """A TCPROS subscriber connected (rospy's thread): mark its socket with the topic's transport priority,
        and pace it when it crosses one of the profile's links of limited bandwidth."""
        if sock is None:
            return
        if mark_socket(sock, self.priority):
            _log.debug("micros_rt: topic %s: TCPROS link to %s marked TOS 0x%02x (%s)", self.guid,
                       getattr(conn, "endpoint_id", "?"), priority_tos(self.priority), self.priority.name)
        paced = self._pacer.attach(sock, self.guid, self.priority) if self._pacer is not None else None
        if paced:
            _log.info("micros_rt: topic %s: TCPROS link to %s %s", self.guid, getattr(conn, "endpoint_id", "?"),
                      paced)

    @property
    def closed(self) -> bool:
        return self._impl is None or bool(self._impl.closed)

    def links(self) -> int:
        """Connections in rospy's list: TCPROS links and micros_rt's DDS pseudo-connections."""
        return 0 if self._impl is None else len(self._impl.connections)

    def reaches(self, node: str) -> bool:
        """Whether a message published now reaches subscriber ``node`` (rospy's ``has_connection``, which counts a
        shared-memory or DDS link once its subscriber attached or matched)."""
        impl = self._impl
        return impl is not None and bool(impl.has_connection(node))

    def latched(self) -> Any:
        """The message a latching publisher keeps for new subscribers (None: none yet)."""
        return None if self._impl is None else self._impl.latch

    def prepare(self, msg: Any) -> Any:
        if self.latch or len(self._impl.connections) > self._pseudo_links():
            return msg
        return None

    def send(self, msg: Any) -> None:
        """Publish to the TCPROS links (rospy keeps the latched message even when there are none)."""
        try:
            self._impl.publish(msg)
        except genpy.SerializationError:
            # rospy leaves the half-written message in its per-topic buffer, and its next publish() sends those
            # bytes ahead of its own: the subscriber reads garbage and drops the link (found by tests/contract)
            buff = self._impl.buff
            buff.seek(0)
            buff.truncate(0)
            raise
        except rospy.ROSException as exc:  # rospy's "publish() to a closed topic" (silent at shutdown)
            if not self.closed:
                raise
            raise TransportError(f"topic {self.guid}: its TCPROS writer is closed (the publication was "
                                 f"unregistered); nothing was sent") from exc

    def close(self) -> None:
        self._pub.unregister()
