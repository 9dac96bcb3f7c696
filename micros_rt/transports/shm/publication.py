"""The shared-memory side of a publication: a channel per subscriber process of this host and user that chose
SHM, and its link in rospy's connection list.

Importing this module imports no iceoryx2: the writer is made when a first subscriber chooses SHM."""

from __future__ import annotations

import os
import threading
from typing import TYPE_CHECKING, Dict, Optional, Tuple

from ...exceptions import MicrosRtError
from ...log import nonblocking_logger
from ...negotiation import SHM, OfferJudge, PublicationFacts, Verdict
from ...qos import is_lossless
from ..negotiated import PublicationHost, PublicationSide
from ..tcpros import patches
from ..tcpros.patches import short
from ..links import PseudoLink, remove_link, attach_link
from .host import ATTACH_TIMEOUT, host_identity, unavailable_reason
from .offer import ShmAnswer, ShmOffer, decide_shm
from .vetting import vetting

if TYPE_CHECKING:
    from .channel import ShmChannel, ShmWriter

__all__ = ["ShmPublication"]

_log = nonblocking_logger("rosout.micros_rt")

#: Most channels of one publication that may wait for their subscriber's port at once: a real subscriber
#: attaches within a second or two (a 60-node graph starting on 2 cores: within ATTACH_TIMEOUT); more waiting
#: means offers nobody reads (issue 46: 1,000 forged ones made 4,000 files in /dev/shm and 510 MB of RSS).
MAX_PENDING_CHANNELS = 16


class ShmPublication(PublicationSide):
    """A publication's shared-memory writer and links (see the module's text)."""

    protocol = SHM

    def __init__(self, host: PublicationHost, *, refusal: Optional[Verdict] = None) -> None:
        super().__init__(host, refusal=refusal)
        self.lock = threading.Lock()
        #: made when a first subscriber chooses SHM
        self.shm: "Optional[ShmWriter]" = None
        self.links: Dict[str, PseudoLink] = {}  # subscriber caller id -> SHM link
        #: offers refused although the rules matched: a live link of the caller, too many pending, not vetted
        self.refused_offers = 0

    def negotiated(self, subscriber: str) -> Optional[OfferJudge]:
        if self.refusal is not None:
            return None
        return OfferJudge(parse=lambda params, source: ShmOffer.from_xmlrpc(params, source=source),
                                   judge=lambda offer: self.judge(offer, subscriber))

    def judge(self, offer: ShmOffer, subscriber: str) -> Tuple[Verdict, Optional[ShmAnswer]]:
        """Accept a subscriber of this host and user on a channel of its own, or say why not."""
        host = self.host
        who = short(subscriber)
        unavailable = unavailable_reason()
        if unavailable is None and self.shm is not None and self.shm.failed:
            unavailable = self.shm.failed
        facts = PublicationFacts(topic=host.topic, dds_topic="", domain=None, type_name=host.data_class._type,
                                 md5=host.data_class._md5sum, options=host.options, latch=host.latch)
        verdict = decide_shm(offer, facts, host=host_identity(), unavailable=unavailable, subscriber=who)
        if verdict.accepted and offer.held and self._still_held(subscriber, offer):
            # asked again on a publisher update: the subscriber's channel is there and read, keep it
            return verdict, self._answer(offer.held)
        if verdict.accepted:
            refusal = self._screen(offer, subscriber, who)
            if refusal is not None:
                self.refused_offers += 1
                verdict = Verdict(False, "shm-refused", f"topic {host.topic}: {refusal}; serving {who} otherwise")
        if verdict.accepted:
            try:
                channel = self._writer().open_channel(subscriber, offer.pid)
            except MicrosRtError as exc:
                verdict = Verdict(False, "shm-unavailable", f"{exc}; serving {who} otherwise")
        host.remember(subscriber, verdict)
        if not verdict.accepted:
            return verdict, None
        info = (f"SHM connection on channel {channel.name} to {who} ("
                f"{'lossless' if is_lossless(host.queue_size) else f'newest {host.queue_size} kept'}, "
                f"priority {host.options.transport_priority.name})")
        conn = PseudoLink(host.topic, subscriber, "o", info, peer_guid=channel.name,
                                    on_close=self._connection_closed, transport=SHM)
        conn.ready = channel.attached  # a message sent before the subscriber's port attached would not reach it
        with self.lock:
            old = self.links.get(subscriber)
            self.links[subscriber] = conn
        refused = attach_link(host.topic, old, conn, what="SHM", subscriber=who, fallback="the next protocol")
        if refused is not None:
            return refused, None
        return verdict, self._answer(channel.name)

    def _screen(self, offer: ShmOffer, subscriber: str, who: str) -> Optional[str]:
        """Why an offer that the rules accept must still not get a channel (issue 46), or None:

        - the subscriber it names has a live link (its channel attached, its process running) that the offer
          does not name: a subscriber's link is its own, a call naming it does not replace it;
        - :data:`MAX_PENDING_CHANNELS` channels already wait for their subscribers to attach;
        - the ROS master and the named node do not confirm that the offer's process is that node's."""
        shm = self.shm
        live = shm.channel_for(subscriber) if shm is not None else None
        if (live is not None and not live.closed and offer.held != live.name and live.attached()
                and not live.subscriber_dead()):
            return (f"{who} already reads channel {live.name} (process {live.peer_pid}); an offer in its name from "
                    f"process {offer.pid} that does not name that channel does not replace it")
        pending = shm.pending_count() if shm is not None else 0
        if pending >= MAX_PENDING_CHANNELS:
            return (f"{pending} shared-memory channels of this publisher still wait for their subscribers to attach "
                    f"(at most {MAX_PENDING_CHANNELS}; they are closed {ATTACH_TIMEOUT:.0f} s after they were made)")
        return vetting.why_not(subscriber, offer.pid)

    def _answer(self, channel: str) -> ShmAnswer:
        return ShmAnswer(channel=channel, latch=self.host.latch, qos=self.host.options, node=patches.caller_id(),
                         pid=os.getpid())

    def _still_held(self, subscriber: str, offer: ShmOffer) -> bool:
        """The channel ``offer`` says its subscriber reads is this publication's channel for that subscriber
        process, open, its port attached, its link in rospy's list."""
        shm = self.shm
        channel = shm.channel_for(subscriber) if shm is not None else None
        with self.lock:
            linked = subscriber in self.links
        return (channel is not None and linked and channel.name == offer.held and channel.peer_pid == offer.pid
                and not channel.closed and channel.attached())

    def _writer(self) -> "ShmWriter":
        host = self.host
        with self.lock:
            if self.shm is None:
                from .channel import ShmWriter

                self.shm = ShmWriter(host.topic, latch=host.latch, queue_size=host.queue_size,
                                     lossless=is_lossless(host.queue_size)
                                     and not host.options.using_best_effort_protocol)
                last = host.latched_message() if host.latch else None
                if last is not None:
                    self.shm.keep_latched(last)  # published before the first SHM subscriber came
                self.writer = self.shm
                created = True
            else:
                created = False
        if created:
            host.writers_changed()
        return self.shm

    def _connection_closed(self, conn: PseudoLink) -> None:
        with self.lock:
            if self.links.get(conn.endpoint_id) is conn:
                del self.links[conn.endpoint_id]
        shm = self.shm
        if shm is not None:
            for channel in shm.channels():
                if channel.name == conn.peer_guid:
                    shm.close_channel(channel)

    def _channel_gone(self, channel: "ShmChannel") -> None:
        with self.lock:
            conn = self.links.get(channel.subscriber)
        if conn is not None and conn.peer_guid == channel.name:
            _log.debug("micros_rt: topic %s: SHM subscriber %s is gone", self.host.topic, short(channel.subscriber))
            remove_link(self.host.topic, conn, publisher=True)
            conn.close()

    # -- links ---------------------------------------------------------------
    def pseudo_links(self) -> int:
        return len(self.links)  # a dict's len: no lock (TCPROS's prepare asks on every publish)

    def reached(self) -> int:
        shm = self.shm
        return shm.attached_count() if shm is not None and self.pseudo_links() else 0

    def housekeeping(self, now: float) -> None:
        """SHM channels whose subscriber left (a SIGKILLed one's ports are reclaimed first)."""
        if self.shm is not None:
            self.shm.housekeeping(now, self._channel_gone)

    def dropped(self) -> int:
        return self.shm.dropped if self.shm is not None else 0

    def refused(self) -> Tuple[int, int]:
        return self.refused_offers, self.shm.never_attached if self.shm is not None else 0

    def close(self) -> None:
        with self.lock:
            conns = list(self.links.values())
        for conn in conns:
            conn.close()
        self.shm = self.writer = None
