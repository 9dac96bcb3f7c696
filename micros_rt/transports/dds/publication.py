"""The DDS side of a publication: the topic's DDS writer, the DDS links of the subscribers that chose DDS,
and writers of another graph's relay that serve them instead (delegation).

Importing this module imports no DDS library: the writer comes from a :class:`~.backend.DDSBackend` given (or
opened, with ROS 2 visibility off, when a first subscriber takes DDS)."""

from __future__ import annotations

import collections
import dataclasses
import threading
from typing import Any, TYPE_CHECKING, Callable, Dict, Optional, Set, Tuple, Union

from ...exceptions import MicrosRtError
from ...log import nonblocking_logger
from ...negotiation import DDS, OfferJudge, PublicationFacts, RateLimitedLog, Verdict
from ...qos import AdvertiseQoSOptions
from ..base import EndpointSpec
from ..negotiated import PublicationHost, PublicationSide
from ..tcpros import patches
from ..tcpros.patches import short
from ..links import PseudoLink, add_link, remove_link, attach_link
from .offer import (MAX_PENDING_DDS_OFFERS, UNMATCHED_READER_TIMEOUT, DDSAnswer, DDSOffer, DDSOpenFirst, decide,
                    dds_transport)

if TYPE_CHECKING:
    from .backend import DDSBackend, DDSTopicWriter

__all__ = ["DDSPublication", "ForeignWriters", "ForeignSource", "ReaderAlive"]

_log = nonblocking_logger("rosout.micros_rt")
_housekeeping_log = RateLimitedLog(_log, interval=60.0)


@dataclasses.dataclass(frozen=True)
class ForeignWriters:
    """Writers of another ROS graph's relay that already reach this DDS domain's readers of a topic this
    node republishes (an importing relay's): :meth:`micros_rt.Publisher.delegate_dds` serves micros_rt
    subscribers with them, straight, instead of with this node's own writer."""

    via: str                        # the other graph's relay name (its writers' tag ``relay=``)
    writer: str                     # one of those writers now (GUID)
    participant: str                # its participant (GUID)
    topic: str                      # the ROS name of the topic they write (this one's, or another: a renamed import)
    options: AdvertiseQoSOptions    # the QoS those writers offer
    latch: bool


#: ``delegate_dds``'s arguments: the foreign writers now (None: none now), and whether a reader is alive
ForeignSource = Callable[[], Optional[ForeignWriters]]
ReaderAlive = Callable[[str], bool]


class DDSPublication(PublicationSide):
    """A publication's DDS writer and links (see the module's text)."""

    protocol = DDS

    def __init__(self, host: PublicationHost, *, backend: "Optional[DDSBackend]", tag: Dict[str, str],
                 lazy: "Optional[Callable[[], Optional[DDSBackend]]]" = None,
                 refusal: Optional[Verdict] = None) -> None:
        super().__init__(host, refusal=refusal)
        self.lock = threading.Lock()
        self._tag = tag
        self._backend = backend
        #: with ROS 2 visibility off: opens the process's DDS back end when a first subscriber takes DDS
        self._lazy = lazy
        self._opening = threading.Lock()
        self.dds: "Optional[DDSTopicWriter]" = None
        self.connections: Dict[str, PseudoLink] = {}  # subscriber caller id -> DDS link
        # links dropped because discovery had not matched their reader in time, by reader GUID (bounded)
        self._expired: "collections.OrderedDict[str, PseudoLink]" = collections.OrderedDict()
        # delegate(): where the foreign writers are, which reader GUIDs are alive, and the subscribers
        # (caller ids) served by them, not by this publication's own DDS writer
        self._foreign: Optional[Tuple[ForeignSource, ReaderAlive]] = None
        self.delegated: Set[str] = set()
        if backend is not None and refusal is None:
            self._open_writer(backend)

    def _open_writer(self, backend: "DDSBackend") -> None:
        host = self.host
        try:
            self.dds = backend.open_writer(EndpointSpec(host.topic, host.data_class, host.queue_size, host.latch,
                                                        self._tag), host.options)
        except MicrosRtError as exc:
            _log.warning("micros_rt: topic %s will use TCPROS only: %s", host.topic, exc)
        self.writer = self.dds

    def ensure_writer(self) -> bool:
        """Not visible to ROS 2: the DDS writer, made when a first subscriber would take DDS (XML-RPC thread) or
        ROS 2 is seen (housekeeping). True when there is one."""
        with self._opening:  # two subscribers asking at once: one writer, and both wait for it
            opener = self._lazy
            if opener is None or self.dds is not None:
                return self.dds is not None
            backend = opener()
            self._lazy = None
            if backend is None:
                return False  # DDS cannot start here: said once by the participant; the subscriber gets TCPROS
            self._backend = backend
            self._open_writer(backend)
            if self.dds is not None:
                _log.info("micros_rt: topic %s: DDS writer made", self.host.topic)
                replayed = self._replay_latched(None)
                self.host.writers_changed()
                self._replay_latched(replayed)  # a publish() between the two went to the writers before this one
            return self.dds is not None

    def open_now(self) -> bool:
        return self.ensure_writer()

    def _replay_latched(self, done: Any) -> Any:
        """A latched topic's last message, published before this writer existed (ROS 2 appeared later, under
        ``auto``), into the writer's history, where a late ROS 2 subscriber (transient_local) finds it, as a late
        TCPROS subscriber gets it from rospy. ``done``: the message already written (not again)."""
        latched = self.host.latched_message() if self.host.latch else None
        if latched is None or latched is done or self.dds is None:
            return done
        data = self.dds.prepare(latched)
        if data is not None:
            self.dds.send(data)
        return latched

    def sending(self) -> bool:
        """The own writer stays out while every DDS subscriber is served by foreign writers (it would send each
        message a second time to readers that ignore it)."""
        if self.dds is None:
            return False
        with self.lock:
            return not (self._foreign is not None and not self.host.latch
                        and all(sub in self.delegated for sub in self.connections))

    def delegate(self, source: ForeignSource, alive: ReaderAlive) -> None:
        self._foreign = (source, alive)
        self.host.writers_changed()

    def delegated_links(self) -> int:
        with self.lock:
            return len(self.delegated)

    # -- negotiation (XML-RPC threads) -------------------------------------
    def facts(self) -> PublicationFacts:
        dds, host = self.dds, self.host
        with self.lock:
            pending = sum(1 for c in self.connections.values() if not c.seen)
        return PublicationFacts(
            topic=host.topic, dds_topic=dds.dds_topic if dds else "",
            domain=self._backend.domain_id if dds is not None and self._backend else None,
            type_name=dds.dds_type.type_name if dds else "", md5=host.data_class._md5sum,
            options=host.options, latch=host.latch, pending=pending)

    def negotiated(self, subscriber: str) -> Optional[OfferJudge]:
        if self.refusal is not None:
            self.host.remember(subscriber, self.refusal)
            return None
        return dds_transport(lambda offer: self.judge(offer, subscriber))

    def judge(self, offer: DDSOffer, subscriber: str) -> Tuple[Verdict, Optional[Union[DDSAnswer, DDSOpenFirst]]]:
        if self.dds is None and self._lazy is not None:
            self.ensure_writer()
        facts = self.facts()
        if offer.lazy:
            # a subscriber with no DDS reader yet: say whether DDS would do; it opens its reader and asks again
            full = dataclasses.replace(offer, topic=facts.dds_topic, type_name=facts.type_name)
            verdict = decide(full, facts, subscriber=short(subscriber))
            self.host.remember(subscriber, verdict)
            return verdict, DDSOpenFirst() if verdict.accepted else None
        foreign = self._foreign[0]() if self._foreign is not None and facts.domain is not None else None
        if foreign is not None and (foreign.topic == self.host.topic or offer.follow):
            # the other graph's writers first: no hop through this process when the subscriber can take them
            # (on another topic: a subscriber that opens a reader there)
            direct = decide(offer, dataclasses.replace(facts, options=foreign.options, latch=foreign.latch),
                            subscriber=short(subscriber))
            if direct.accepted:
                return self._link(offer, subscriber, direct, foreign)
            _log.debug("micros_rt: topic %s: %s's writers cannot serve %s (%s); serving it from this node",
                       self.host.topic, foreign.via, short(subscriber), direct.reason)
        return self._link(offer, subscriber, decide(offer, facts, subscriber=short(subscriber)), None)

    def _link(self, offer: DDSOffer, subscriber: str, verdict: Verdict,
              foreign: Optional[ForeignWriters]) -> Tuple[Verdict, Optional[DDSAnswer]]:
        """Record ``verdict``; when it accepts, make the DDS link (served by ``foreign`` writers, or by ours)."""
        host = self.host
        host.remember(subscriber, verdict)
        dds = self.dds
        if not verdict.accepted or dds is None:
            return verdict, None
        # rospy's publisher may still be registering (a subscriber can ask the moment the master knows
        # us): its topic impl already exists, which is all the pseudo-connection needs
        if foreign is None:
            info = (f"DDS connection on topic {dds.dds_topic} to reader {offer.reader} (writer {dds.guid}, "
                    f"{'best effort' if host.options.using_best_effort_protocol else 'reliable'}, "
                    f"priority {host.options.transport_priority.name})")
        else:
            info = (f"DDS connection on topic {foreign.topic} to reader {offer.reader}, served straight by "
                    f"the writers of graph {foreign.via}'s relay (now {foreign.writer}, priority "
                    f"{foreign.options.transport_priority.name}); none of it passes through this node")
        conn = PseudoLink(host.topic, subscriber, "o", info, peer_guid=offer.reader,
                                    on_close=self._connection_closed)
        # a message written before the reader matched would not reach it: rospy's has_connection waits for that
        conn.ready = lambda: conn.seen or conn.peer_guid in self._reached([conn], dds)
        with self.lock:
            old = self.connections.get(subscriber)
            self.connections[subscriber] = conn
            if foreign is None:
                self.delegated.discard(subscriber)
            else:
                self.delegated.add(subscriber)
            dds.want(True)  # a subscriber served over DDS now: write (housekeeping keeps deciding)
        host.writers_changed()
        refused = attach_link(host.topic, old, conn, what="DDS", subscriber=short(subscriber),
                                      fallback="TCPROS")
        if refused is not None:
            return refused, None
        if foreign is not None:
            return verdict, DDSAnswer(writer=foreign.writer, participant=foreign.participant, latch=foreign.latch,
                                      qos=foreign.options, node=patches.caller_id(), via=foreign.via,
                                      topic="" if foreign.topic == host.topic else foreign.topic)
        return verdict, DDSAnswer(writer=dds.guid, participant=dds.participant.guid,
                                  latch=host.latch, qos=host.options, node=patches.caller_id())

    def _connection_closed(self, conn: PseudoLink) -> None:
        with self.lock:
            if self.connections.get(conn.endpoint_id) is conn:
                del self.connections[conn.endpoint_id]
                self.delegated.discard(conn.endpoint_id)
        self.host.writers_changed()

    # -- links ---------------------------------------------------------------
    def _reached(self, conns: "list[PseudoLink]", dds: "DDSTopicWriter") -> Set[str]:
        """Reader GUIDs among ``conns`` that are there now: matched by our writer, or, for subscribers
        served by foreign writers, alive in DDS discovery."""
        matched = dds.matched_peers()
        if self._foreign is not None and self.delegated:
            alive = self._foreign[1]
            matched |= {c.peer_guid for c in conns if c.endpoint_id in self.delegated and alive(c.peer_guid)}
        return matched

    def pseudo_links(self) -> int:
        return len(self.connections)  # a dict's len: no lock (TCPROS's prepare asks on every publish)

    def reached(self) -> int:
        """DDS subscribers whose reader the writer has matched (negotiation precedes DDS discovery by a few
        milliseconds; counting those early would let a "wait for a subscriber, then publish" loop lose its
        first messages)."""
        dds = self.dds
        with self.lock:
            conns = list(self.connections.values())
        if not conns or dds is None:
            return 0
        matched = self._reached(conns, dds)
        return sum(1 for c in conns if c.peer_guid in matched)

    def link_states(self) -> Optional[Dict[str, bool]]:
        with self.lock:
            return {sub: conn.seen for sub, conn in self.connections.items()}

    def _gate(self) -> None:
        """Write to DDS only when a matched reader wants it: a ROS 2 (untagged) reader, or a micros_rt reader this
        publication serves over DDS. A micros_rt reader of this graph served over shared memory or TCPROS (its
        reader exists for ROS 2's sake) drops DDS samples of a writer its node did not negotiate with: without
        this, every message to a local SHM subscriber was also encoded and sent over loopback DDS, for nothing."""
        dds = self.dds
        if dds is None:
            return
        if self.host.latch or self._foreign is not None:
            dds.want(True)
            return
        graph = self._tag.get("graph")
        # under the lock a DDS link is added with (_link): a decision never undoes a link made meanwhile; and it
        # stands only if no reader matched while it was made (the writer counts match changes)
        with self.lock:
            generation = dds.match_generation()
            served = {c.peer_guid for c in self.connections.values()}
            readers = dds.matched_readers()
            dds.want(any(tag is None or guid in served or tag.get("graph") != graph or "relay" in tag
                         or "relay_import" in tag for guid, tag in readers.items()), generation)

    def housekeeping(self, now: float) -> None:
        """Drop DDS links whose reader went away, or that discovery never matched in time (an offer nobody
        follows up must not stay a connection forever); decide whether DDS readers want the samples."""
        self._gate()
        dds, topic = self.dds, self.host.topic
        with self.lock:
            conns = list(self.connections.values())
        if dds is None or (not conns and not self._expired):
            return
        matched = self._reached(conns, dds)
        for conn in conns:
            if conn.peer_guid in matched:
                conn.seen = True
                continue
            if conn.seen:
                _log.debug("micros_rt: topic %s: DDS subscriber %s is gone", topic, short(conn.endpoint_id))
            elif now - conn.created > UNMATCHED_READER_TIMEOUT:
                _housekeeping_log.warning(
                    (topic, "unmatched"),
                    f"topic {topic}: DDS subscriber {short(conn.endpoint_id)} was accepted but its reader "
                    f"{conn.peer_guid} never appeared in DDS discovery within {UNMATCHED_READER_TIMEOUT:.0f} s; "
                    f"dropped the connection (check both nodes' ROS_IP/CYCLONEDDS_URI and ROS_DOMAIN_ID)")
                self._expired[conn.peer_guid] = conn
                while len(self._expired) > MAX_PENDING_DDS_OFFERS:
                    self._expired.popitem(last=False)
            else:
                continue
            remove_link(topic, conn, publisher=True)
            conn.close()
        # a real subscriber on a slow or lossy network can be discovered after the bound: take it back
        for guid in [g for g in self._expired if g in matched]:
            old = self._expired.pop(guid)
            if old.endpoint_id in self.connections:
                continue
            late = PseudoLink(topic, old.endpoint_id, "o", old.info, peer_guid=guid,
                                        on_close=self._connection_closed)
            late.seen = True
            with self.lock:
                self.connections[old.endpoint_id] = late
            if add_link(topic, late, publisher=True):
                _log.warning("micros_rt: topic %s: DDS subscriber %s was discovered late; connected again",
                             topic, short(old.endpoint_id))
            else:
                late.close()

    def close(self) -> None:
        with self.lock:
            conns = list(self.connections.values())
        for conn in conns:
            conn.close()
        self.dds = self.writer = None
