"""The link every negotiated transport keeps per peer (shared memory, DDS, a plug-in's): a :class:`PseudoLink` in
rospy's connection list of the topic, so ``rosnode info``, ``get_num_connections`` and actionlib's checks see the
peer, while the transport itself carries the data (it has no socket and writes nothing).

rospy's internals stay in :mod:`micros_rt.transports.tcpros.patches`; this module is what a transport uses:
:func:`add_link` / :func:`remove_link` (a subscriber's link, or any link), :func:`attach_link` (a publisher's link
to a subscriber, in place of the one it had) and :func:`links_of`.
"""

from __future__ import annotations

import itertools
import time
from typing import Any, Callable, List, Optional

from ..log import nonblocking_logger
from ..negotiation import Verdict
from .tcpros import patches

__all__ = ["PseudoLink", "add_link", "attach_link", "links_of", "remove_link"]

_log = nonblocking_logger("rosout.micros_rt")
_ids = itertools.count(100000)


class PseudoLink:
    """A connection in rospy's bookkeeping whose data flows over a negotiated transport (``transport``: "SHM",
    "DDS", a plug-in's protocol name).

    It has no socket (``fileno()`` is None) and writes nothing: the transport's writer carries the data once for
    all of its readers, however many of these exist.
    """

    #: what rospy's bookkeeping and :mod:`~micros_rt.transports.tcpros.patches` tell it apart by
    pseudo_link = True
    transport_type = "DDS"
    #: rospy's connection interface: ``Subscriber.add_callback`` replays each connection's ``latch`` (#1852).
    #: A second rospy Subscriber of a topic made while such links are being added read it and raised
    #: AttributeError (a 30-node graph lost a node to it). A transport's latched message is replayed by the
    #: subscription itself (``_Subscription.replay_latched``).
    latch = None

    def __init__(self, topic: str, endpoint_id: str, direction: str, info: str, peer_guid: str = "",
                 on_close: Optional[Callable[["PseudoLink"], None]] = None, *, transport: str = "DDS",
                 callerid_pub: str = "") -> None:
        self.id = next(_ids)
        self.transport_type = transport
        self.peer_guid = peer_guid  # the peer this link reads or writes: a DDS reader or writer, a channel
        self.seen = False  # has the transport's discovery matched the peer yet?
        self.created = time.monotonic()
        self.name = topic
        self.endpoint_id = endpoint_id
        self.direction = direction  # 'i' inbound (subscriber side) / 'o' outbound
        self.info = info
        self.done = False
        self.cleanup_cb: Optional[Callable[[Any], None]] = None
        self.stat_bytes = 0
        self.stat_num_msg = 0
        # rospy's connection interface: an inbound TCPROS connection's ``callerid_pub`` is the publisher's node name
        # (from its connection header), ``endpoint_id`` its URI. actionlib's wait_for_server compares the result and
        # feedback connections' callerid_pub with the server's node name: a URI there kept it waiting forever.
        self.callerid_pub = callerid_pub or endpoint_id
        #: whether a message published now reaches the peer (an outbound link: the subscriber attached or matched);
        #: what rospy's ``has_connection`` reads (patched in :mod:`~micros_rt.transports.tcpros.patches`)
        self.ready: Callable[[], bool] = lambda: True
        self._on_close = on_close

    def fileno(self) -> None:
        return None

    def get_transport_info(self) -> str:
        return self.info

    def set_cleanup_callback(self, cb: Callable[[Any], None]) -> None:
        self.cleanup_cb = cb

    def write_data(self, data: bytes) -> bool:
        return True

    def close(self) -> None:
        if self.done:
            return
        self.done = True
        if self._on_close is not None:
            self._on_close(self)
        if self.cleanup_cb is not None:
            try:
                self.cleanup_cb(self)
            except Exception:  # rospy's own cleanup; never break our close
                _log.debug("cleanup callback failed", exc_info=True)


def add_link(topic: str, link: PseudoLink, *, publisher: bool) -> bool:
    """Put ``link`` into rospy's connection list of ``topic`` (its publisher's or its subscriber's); False when
    rospy has no such endpoint (it was unregistered)."""
    return patches.add_pseudo_connection(topic, link, publisher=publisher)


def remove_link(topic: str, link: PseudoLink, *, publisher: bool) -> None:
    """Take ``link`` out of rospy's connection list of ``topic`` (harmless when it is not there)."""
    patches.remove_pseudo_connection(topic, link, publisher=publisher)


def attach_link(topic: str, old: Optional[PseudoLink], link: PseudoLink, *, what: str, subscriber: str,
                fallback: str) -> Optional[Verdict]:
    """Put a subscriber's new link into rospy's publisher connection list of ``topic`` in place of ``old``; a
    Verdict in words when rospy has no publisher left to attach it to (the link is closed then)."""
    if old is not None:
        remove_link(topic, old, publisher=True)
        old.close()
    if add_link(topic, link, publisher=True):
        return None
    link.close()
    return Verdict(False, "closing", f"topic {topic}: no rospy publisher to attach the {what} link of "
                                     f"{subscriber} to (unregistered); using {fallback}")


def links_of(topic: str, *, publisher: bool) -> List[PseudoLink]:
    """The negotiated transports' links of ``topic`` in rospy's connection list."""
    return [c for c in patches.topic_connections(topic, publisher=publisher) if isinstance(c, PseudoLink)]
