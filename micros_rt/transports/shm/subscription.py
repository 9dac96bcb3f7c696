"""The shared-memory side of a subscription: its offer (this host and user), and a link per publisher that
chose SHM, each handing messages to the subscription's delivery thread.

Importing this module imports no iceoryx2: a link opens it when a publisher answers SHM."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional, Tuple

from ...exceptions import MicrosRtError
from ...log import nonblocking_logger
from ...negotiation import SHM
from ...qos import UNBOUNDED_QUEUE_DEPTH
from ..base import PushReader
from ..negotiated import SubscriptionHost, SubscriptionSide
from ..tcpros import patches
from ..links import PseudoLink, add_link, remove_link
from .host import host_identity, process_alive, unavailable_reason
from .offer import ShmAnswer, ShmOffer

if TYPE_CHECKING:
    from .channel import ShmLink

__all__ = ["ShmSubscription"]

_log = nonblocking_logger("rosout.micros_rt")

#: ``(link, inlet) -> True`` when the subscription's delivery thread waits on the link itself (and admits what
#: it takes as ``inlet``'s); False: the link's own thread puts its messages into ``inlet``
PollLink = Callable[["ShmLink", PushReader], bool]


class ShmSubscription(SubscriptionSide):
    """A subscription's shared-memory links (see the module's text)."""

    protocol = SHM
    words = "shared memory"

    def __init__(self, host: SubscriptionHost, *, poll: PollLink) -> None:
        super().__init__(host)
        self._poll = poll
        # one link thread per publisher that chose SHM for us, each waiting for room as TCPROS's
        self.inlet = PushReader(SHM, host.depth or UNBOUNDED_QUEUE_DEPTH, host.wake, blocking=True)
        self.links: Dict[str, "ShmLink"] = {}  # publisher URI -> link

    def offer(self, held: str) -> Optional[List[Any]]:
        if unavailable_reason() is not None:
            return None
        host = self.host
        return ShmOffer(host=host_identity(), md5=host.data_class._md5sum, type_name=host.data_class._type,
                        qos=host.effective, pid=os.getpid(), held=held).to_xmlrpc()

    def read_answer(self, params: Any, source: str) -> ShmAnswer:
        return ShmAnswer.from_xmlrpc(params, source=source)

    def peer_of(self, answer: Any) -> str:
        return str(answer.channel)

    def pushed(self) -> Tuple[PushReader, ...]:
        return (self.inlet,)

    def connect(self, pub_uri: str, answer: Any) -> Tuple[int, str, int]:
        """Open the shared-memory link to the channel the publisher made for this subscription."""
        from .channel import ShmLink

        host = self.host
        if host.closed:
            return 0, "subscriber closed", 0
        node = answer.node or pub_uri
        header = {"callerid": node, "topic": host.topic, "type": host.data_class._type,
                  "md5sum": host.data_class._md5sum, "transport": SHM}
        conn = PseudoLink(host.topic, pub_uri, "i", f"SHM connection on channel {answer.channel} from "
                                    f"{node}", peer_guid=answer.channel, on_close=self._connection_closed,
                                    transport=SHM, callerid_pub=node)
        put: Callable[[Any, int, Any], None] = self.inlet.put

        def keep_latched(msg: Any) -> None:
            conn.latch = msg  # for callbacks added later (replay_latched), as rospy keeps it per connection

        def dropped(n: int) -> None:
            self.inlet.dropped += n

        try:
            link = ShmLink(host.topic, answer.channel, host.data_class, header=header, qos=answer.qos, put=put,
                           on_drop=dropped, on_gone=lambda gone: self._link_gone(conn, gone), peer_pid=answer.pid,
                           on_latched=keep_latched if answer.latch else None)
        except MicrosRtError as exc:
            _log.warning("micros_rt: %s; the publisher %s is asked again", exc, pub_uri)
            return 0, str(exc), 0
        with host.lock:
            old = self.links.get(pub_uri)
            self.links[pub_uri] = link
        if old is not None:
            old.close()
        if not self._poll(link, self.inlet):
            link.start_thread()  # the delivery thread waits on Cyclone's wait set: the link wakes it
        host.raise_priority(answer.qos)
        if not add_link(host.topic, conn, publisher=False):
            conn.close()
            return 0, "subscriber closed", 0
        _log.debug("micros_rt: topic %s: receiving from %s over shared memory", host.topic, pub_uri)
        host.wake()
        return 1, f"Connected topic[{host.topic}] over SHM", 0

    def _connection_closed(self, conn: PseudoLink) -> None:
        with self.host.lock:
            link = self.links.get(conn.endpoint_id)
            if link is not None and link.channel == conn.peer_guid:
                del self.links[conn.endpoint_id]
            else:
                link = None
        if link is not None:
            link.close()

    def _link_gone(self, conn: PseudoLink, link: "Optional[ShmLink]" = None) -> None:
        """The publisher's end went (it unregistered, its process died, or it closed this subscriber's channel:
        /dev/shm full, a forged offer in our name on old publishers): drop the connection; while the publisher's
        process still runs, ask it for a link again at once, as rospy's TCPROS subscriber reconnects (a
        restarted publisher is connected when the master names it anew)."""
        if self.host.closed or conn.done:
            return
        _log.debug("micros_rt: topic %s: SHM publisher %s is gone", self.host.topic, conn.endpoint_id)
        remove_link(self.host.topic, conn, publisher=False)
        conn.close()
        if link is None or not process_alive(link.peer_pid) or link.peer_pid == 0:
            return
        topic, pub_uri = self.host.topic, conn.endpoint_id

        def done(code: int, msg: str) -> None:
            if code == 1:
                _log.warning("micros_rt: topic %s: the shared-memory link from %s went while its publisher runs; "
                             "connected again (%s)", topic, pub_uri, msg)
            else:
                _log.info("micros_rt: topic %s: the shared-memory link from %s went; asked again: %s", topic,
                          pub_uri, msg)

        patches.connect_again(topic, pub_uri, done)

    def close(self) -> None:
        with self.host.lock:
            links, self.links = list(self.links.values()), {}
        for link in links:
            link.close()
