"""A micros_rt publication: per topic and process, the rospy publisher (master registration, TCPROS for
stock peers and TCPROS-preferring subscribers) and a back-end writer (DDS) for micros_rt subscribers."""

from __future__ import annotations

import collections
import dataclasses
import os
import struct
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, Optional, Set, Tuple, Type, Union

import genpy
import rospy
import rospy.topics

from ..transports.tcpros import patches
from ..transports.tcpros.writer import TcprosWriter
from .lanes import Lane, sender_for
from .registry import EndpointRegistry
from ..transports.tcpros.patches import short
from .stats import PublisherStatistics
from ..transports.base import EndpointSpec, ProfileBackend, TransportWriter
from ..exceptions import MicrosRtError
from ..negotiation import (
    MAX_PENDING_DDS_OFFERS,
    UNMATCHED_READER_TIMEOUT,
    DDS,
    SHM,
    ShmAnswer,
    ShmOffer,
    decide_shm,
    DDSAnswer,
    DDSOffer,
    DDSOpenFirst,
    NegotiatedTransport,
    PublicationFacts,
    RateLimitedLog,
    Verdict,
    decide,
    dds_transport,
    remember_verdict,
)
from ..qos import AdvertiseQoSOptions, is_lossless
from ..log import nonblocking_logger

if TYPE_CHECKING:
    from ..transports.pacing import LinkPacer
    from ..transports.dds.backend import DDSBackend, DDSTopicWriter
    from ..transports.shm.channel import ShmChannel, ShmWriter

__all__ = ["Publisher", "ForeignWriters"]

_log = nonblocking_logger("rosout.micros_rt")
_housekeeping_log = RateLimitedLog(_log, interval=60.0)


@dataclasses.dataclass(frozen=True)
class ForeignWriters:
    """Writers of another ROS graph's relay that already reach this DDS domain's readers of a topic this
    node republishes (an importing relay's): :meth:`Publisher.delegate_dds` serves micros_rt subscribers
    with them, straight, instead of with this node's own writer."""

    via: str                        # the other graph's relay name (its writers' tag ``relay=``)
    writer: str                     # one of those writers now (GUID)
    participant: str                # its participant (GUID)
    topic: str                      # the ROS name of the topic they write (this one's, or another: a renamed import)
    options: AdvertiseQoSOptions    # the QoS those writers offer
    latch: bool


#: ``delegate_dds``'s arguments: the foreign writers now (None: none now), and whether a reader is alive
ForeignSource = Callable[[], Optional[ForeignWriters]]
ReaderAlive = Callable[[str], bool]


class _Publication:
    """Per topic and process: the rospy publisher and the DDS writer. Owned by the registry."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int], latch: bool,
                 options: AdvertiseQoSOptions, *, dds: "Optional[DDSBackend]", tag: Dict[str, str],
                 extra: Tuple[ProfileBackend, ...] = (), pacer: "Optional[LinkPacer]" = None,
                 off_dds: Optional[str] = None) -> None:
        self.topic = topic
        #: why this topic has no DDS writer by choice (the node's profile), in words; None: it has one if it can
        self.off_dds = off_dds
        self._pacer = pacer
        self.data_class = data_class
        self.latch = latch
        self.options = options
        self.queue_size = queue_size
        self.lock = threading.Lock()
        self.connections: Dict[str, patches.DDSConnection] = {}  # subscriber caller id -> DDS link
        # links dropped because discovery had not matched their reader in time, by reader GUID (bounded)
        self._expired: "collections.OrderedDict[str, patches.DDSConnection]" = collections.OrderedDict()
        # the last DDS verdict per subscriber caller id, for `micros-rt topic info` (bounded)
        self.verdicts: "collections.OrderedDict[str, Verdict]" = collections.OrderedDict()
        self.published = 0
        self.blocked_seconds = 0.0
        self.closed = False
        self._publish_lock = threading.Lock()
        self.tcpros: Optional[TcprosWriter] = None
        #: shared memory: the writer (made when a first subscriber chooses SHM) and its pseudo-connections
        self.shm: "Optional[ShmWriter]" = None
        self.shm_links: Dict[str, patches.DDSConnection] = {}  # subscriber caller id -> SHM link
        #: why this topic serves no SHM by choice (the node's profile), in words; None: it does if it can
        self.off_shm: Optional[str] = None
        self.dds: "Optional[DDSTopicWriter]" = None
        self._dds_backend = dds
        self._tag = tag
        #: with ROS 2 visibility off: opens the process's DDS back end when a first subscriber takes DDS
        self.lazy_dds: "Optional[Callable[[], Optional[DDSBackend]]]" = None
        self._dds_opening = threading.Lock()
        if dds is not None:
            self._open_dds_writer(dds)
        # writers of the transports the YAML profile attaches to this topic (MQTT): every message is mirrored
        spec = EndpointSpec(topic, data_class, queue_size, latch, tag)
        self.mirrors: Tuple[TransportWriter, ...] = tuple(
            w for w in (b.open_writer(spec, options) for b in extra) if w is not None)
        self.senders: Tuple[TransportWriter, ...] = ()
        self.lanes: Tuple[Lane, ...] = ()
        self._build_senders()
        #: every writer of the topic, in sending order: TCPROS first (rospy serializes inside its send and
        #: raises before writing), then the senders
        self.writers: Tuple[TransportWriter, ...] = ()
        # delegate_dds: where the foreign writers are, which reader GUIDs are alive, and the subscribers
        # (caller ids) served by them, not by this publication's own DDS writer
        self._foreign: Optional[Tuple[ForeignSource, ReaderAlive]] = None
        self.delegated: Set[str] = set()

    def _open_dds_writer(self, backend: "DDSBackend") -> None:
        try:
            self.dds = backend.open_writer(EndpointSpec(self.topic, self.data_class, self.queue_size, self.latch,
                                                        self._tag), self.options)
        except MicrosRtError as exc:
            _log.warning("micros_rt: topic %s will use TCPROS only: %s", self.topic, exc)

    def _build_senders(self) -> None:
        """The DDS writer, then the mirrors, each behind a lane when it can say "no room now" (DDS): one topic's
        back-pressure never holds another topic's publish(), and a KEEP_LAST publish() never waits (as rospy's)."""
        self.senders = tuple(sender_for(w, topic=self.topic, queue_size=self.queue_size, options=self.options)
                             for w in ((self.dds,) if self.dds is not None else ()) + self.mirrors)
        self.lanes = tuple(s for s in self.senders if isinstance(s, Lane))

    def _ensure_dds(self) -> None:
        """With ROS 2 visibility off: the DDS writer, made when a first subscriber would take DDS (XML-RPC thread)."""
        with self._dds_opening:  # two subscribers asking at once: one writer, and both wait for it
            opener = self.lazy_dds
            if opener is None or self.dds is not None:
                return
            backend = opener()
            self.lazy_dds = None
            if backend is None:
                return  # DDS cannot start here: said once by the participant; the subscriber gets TCPROS
            self._dds_backend = backend
            self._open_dds_writer(backend)
            if self.dds is not None:
                _log.info("micros_rt: topic %s: DDS writer made for a subscriber that takes DDS", self.topic)
                self._build_senders()
                self._refresh_writers()

    def start(self) -> None:
        self.tcpros = TcprosWriter(self.topic, self.data_class, self.queue_size, self.latch,
                                   pseudo_links=lambda: len(self.connections) + len(self.shm_links),
                                   priority=self.options.transport_priority, pacer=self._pacer)
        self._refresh_writers()

    def _refresh_writers(self) -> None:
        """The writers ``publish`` uses: the own DDS writer stays out while every DDS subscriber is served
        by foreign writers (it would send each message a second time to readers that ignore it)."""
        if self.tcpros is None:
            return
        with self.lock:
            idle = (self._foreign is not None and not self.latch and self.dds is not None
                    and all(sub in self.delegated for sub in self.connections))
        # the DDS writer's sender is the first when there is one (__init__)
        shm: Tuple[TransportWriter, ...] = (self.shm,) if self.shm is not None else ()
        self.writers = (self.tcpros,) + shm + (self.senders[1:] if idle else self.senders)

    def delegate_dds(self, source: ForeignSource, alive: ReaderAlive) -> None:
        self._foreign = (source, alive)
        self._refresh_writers()

    # -- negotiation (XML-RPC threads) -------------------------------------
    def facts(self) -> PublicationFacts:
        dds = self.dds
        with self.lock:
            pending = sum(1 for c in self.connections.values() if not c.seen)
        return PublicationFacts(
            topic=self.topic, dds_topic=dds.dds_topic if dds else "",
            domain=self._dds_backend.domain_id if dds is not None and self._dds_backend else None,
            type_name=dds.dds_type.type_name if dds else "", md5=self.data_class._md5sum,
            options=self.options, latch=self.latch, pending=pending)

    def negotiated_transports(self, subscriber: str) -> Dict[str, NegotiatedTransport]:
        """What ``requestTopic`` may negotiate for this topic with ``subscriber``: DDS, judged here (none when
        the profile keeps the topic off DDS: the subscriber's DDS entry is skipped as a stock publisher would,
        with no warning, and ``micros-rt topic info`` shows why)."""
        negotiated: Dict[str, NegotiatedTransport] = {}
        if self.off_shm is None:
            negotiated[SHM] = NegotiatedTransport(
                parse=lambda params, source: ShmOffer.from_xmlrpc(params, source=source),
                judge=lambda offer: self.judge_shm(offer, subscriber))
        if self.off_dds is not None:
            with self.lock:
                remember_verdict(self.verdicts, short(subscriber, 256), Verdict(False, "profile", self.off_dds))
            return negotiated
        negotiated[DDS] = dds_transport(lambda offer: self.judge(offer, subscriber))
        return negotiated

    # -- shared memory ------------------------------------------------------
    def judge_shm(self, offer: ShmOffer, subscriber: str) -> Tuple[Verdict, Optional[ShmAnswer]]:
        """Accept a subscriber of this host and user on a channel of its own, or say why not."""
        from ..transports import shm as shm_transport

        who = short(subscriber)
        unavailable = shm_transport.unavailable_reason()
        if unavailable is None and self.shm is not None and self.shm.failed:
            unavailable = self.shm.failed
        facts = PublicationFacts(topic=self.topic, dds_topic="", domain=None, type_name=self.data_class._type,
                                 md5=self.data_class._md5sum, options=self.options, latch=self.latch)
        verdict = decide_shm(offer, facts, host=shm_transport.host_identity(), unavailable=unavailable,
                             subscriber=who)
        if verdict.accepted and offer.held and self._still_held(subscriber, offer):
            # asked again on a publisher update: the subscriber's channel is there and read, keep it
            return verdict, ShmAnswer(channel=offer.held, latch=self.latch, qos=self.options,
                                      node=patches.caller_id(), pid=os.getpid())
        if verdict.accepted:
            try:
                channel = self._shm_writer().open_channel(subscriber, offer.pid)
            except MicrosRtError as exc:
                verdict = Verdict(False, "shm-unavailable", f"{exc}; serving {who} otherwise")
        with self.lock:
            remember_verdict(self.verdicts, short(subscriber, 256), verdict)
        if not verdict.accepted:
            return verdict, None
        info = (f"SHM connection on channel {channel.name} to {who} ("
                f"{'lossless' if is_lossless(self.queue_size) else f'newest {self.queue_size} kept'}, "
                f"priority {self.options.transport_priority.name})")
        conn = patches.DDSConnection(self.topic, subscriber, "o", info, peer_guid=channel.name,
                                    on_close=self._shm_connection_closed, transport=SHM)
        with self.lock:
            old = self.shm_links.get(subscriber)
            self.shm_links[subscriber] = conn
        refused = self._attach_link(old, conn, what="SHM", subscriber=who, fallback="the next protocol")
        if refused is not None:
            return refused, None
        return verdict, ShmAnswer(channel=channel.name, latch=self.latch, qos=self.options, node=patches.caller_id(),
                                  pid=os.getpid())

    def _still_held(self, subscriber: str, offer: ShmOffer) -> bool:
        """The channel ``offer`` says its subscriber reads is this publication's channel for that subscriber
        process, open, its port attached, its link in rospy's list."""
        shm = self.shm
        channel = shm.channel_for(subscriber) if shm is not None else None
        with self.lock:
            linked = subscriber in self.shm_links
        return (channel is not None and linked and channel.name == offer.held and channel.peer_pid == offer.pid
                and not channel.closed and channel.attached())

    def _attach_link(self, old: Optional[patches.DDSConnection], conn: patches.DDSConnection, *, what: str,
                     subscriber: str, fallback: str) -> Optional[Verdict]:
        """Put a subscriber's new DDS or SHM link into rospy's connection list in place of ``old``; a Verdict
        in words when rospy has no publisher left to attach it to (the link is closed then)."""
        if old is not None:
            patches.remove_pseudo_connection(self.topic, old, publisher=True)
            old.close()
        if patches.add_pseudo_connection(self.topic, conn, publisher=True):
            return None
        conn.close()
        return Verdict(False, "closing", f"topic {self.topic}: no rospy publisher to attach the {what} link of "
                                         f"{subscriber} to (unregistered); using {fallback}")

    def _shm_writer(self) -> "ShmWriter":
        with self.lock:
            if self.shm is None:
                from ..transports.shm.channel import ShmWriter

                self.shm = ShmWriter(self.topic, latch=self.latch, queue_size=self.queue_size,
                                     lossless=is_lossless(self.queue_size) and not self.options.using_best_effort_protocol)
                last = self.tcpros.latched() if self.latch and self.tcpros is not None else None
                if last is not None:
                    self.shm.keep_latched(last)  # published before the first SHM subscriber came
                created = True
            else:
                created = False
        if created:
            self._refresh_writers()
        return self.shm

    def _shm_connection_closed(self, conn: patches.DDSConnection) -> None:
        with self.lock:
            if self.shm_links.get(conn.endpoint_id) is conn:
                del self.shm_links[conn.endpoint_id]
        shm = self.shm
        if shm is not None:
            for channel in shm.channels():
                if channel.name == conn.peer_guid:
                    shm.close_channel(channel)

    def _shm_channel_gone(self, channel: "ShmChannel") -> None:
        with self.lock:
            conn = self.shm_links.get(channel.subscriber)
        if conn is not None and conn.peer_guid == channel.name:
            _log.debug("micros_rt: topic %s: SHM subscriber %s is gone", self.topic, short(channel.subscriber))
            patches.remove_pseudo_connection(self.topic, conn, publisher=True)
            conn.close()

    def judge(self, offer: DDSOffer, subscriber: str) -> Tuple[Verdict, Optional[Union[DDSAnswer, DDSOpenFirst]]]:
        if self.dds is None and self.lazy_dds is not None:
            self._ensure_dds()
        facts = self.facts()
        if offer.lazy:
            # a subscriber with no DDS reader yet: say whether DDS would do; it opens its reader and asks again
            full = dataclasses.replace(offer, topic=facts.dds_topic, type_name=facts.type_name)
            verdict = decide(full, facts, subscriber=short(subscriber))
            with self.lock:
                remember_verdict(self.verdicts, short(subscriber, 256), verdict)
            return verdict, DDSOpenFirst() if verdict.accepted else None
        foreign = self._foreign[0]() if self._foreign is not None and facts.domain is not None else None
        if foreign is not None and (foreign.topic == self.topic or offer.follow):
            # the other graph's writers first: no hop through this process when the subscriber can take them
            # (on another topic: a subscriber that opens a reader there)
            direct = decide(offer, dataclasses.replace(facts, options=foreign.options, latch=foreign.latch),
                            subscriber=short(subscriber))
            if direct.accepted:
                return self._link(offer, subscriber, direct, foreign)
            _log.debug("micros_rt: topic %s: %s's writers cannot serve %s (%s); serving it from this node",
                       self.topic, foreign.via, short(subscriber), direct.reason)
        return self._link(offer, subscriber, decide(offer, facts, subscriber=short(subscriber)), None)

    def _link(self, offer: DDSOffer, subscriber: str, verdict: Verdict,
              foreign: Optional[ForeignWriters]) -> Tuple[Verdict, Optional[DDSAnswer]]:
        """Record ``verdict``; when it accepts, make the DDS link (served by ``foreign`` writers, or by ours)."""
        with self.lock:
            remember_verdict(self.verdicts, short(subscriber, 256), verdict)
        dds = self.dds
        if not verdict.accepted or dds is None:
            return verdict, None
        # rospy's publisher may still be registering (a subscriber can ask the moment the master knows
        # us): its topic impl already exists, which is all the pseudo-connection needs
        if foreign is None:
            info = (f"DDS connection on topic {dds.dds_topic} to reader {offer.reader} (writer {dds.guid}, "
                    f"{'best effort' if self.options.using_best_effort_protocol else 'reliable'}, "
                    f"priority {self.options.transport_priority.name})")
        else:
            info = (f"DDS connection on topic {foreign.topic} to reader {offer.reader}, served straight by "
                    f"the writers of graph {foreign.via}'s relay (now {foreign.writer}, priority "
                    f"{foreign.options.transport_priority.name}); none of it passes through this node")
        conn = patches.DDSConnection(self.topic, subscriber, "o", info, peer_guid=offer.reader,
                                    on_close=self._connection_closed)
        with self.lock:
            old = self.connections.get(subscriber)
            self.connections[subscriber] = conn
            if foreign is None:
                self.delegated.discard(subscriber)
            else:
                self.delegated.add(subscriber)
            dds.want(True)  # a subscriber served over DDS now: write (housekeeping keeps deciding)
        self._refresh_writers()
        refused = self._attach_link(old, conn, what="DDS", subscriber=short(subscriber), fallback="TCPROS")
        if refused is not None:
            return refused, None
        assert self._dds_backend is not None
        if foreign is not None:
            return verdict, DDSAnswer(writer=foreign.writer, participant=foreign.participant, latch=foreign.latch,
                                      qos=foreign.options, node=patches.caller_id(), via=foreign.via,
                                      topic="" if foreign.topic == self.topic else foreign.topic)
        return verdict, DDSAnswer(writer=dds.guid, participant=dds.participant.guid,
                                  latch=self.latch, qos=self.options, node=patches.caller_id())

    def on_tcpros_connection(self, conn: Any, sock: Any) -> None:
        """A TCPROS subscriber connected (rospy's thread): the TCPROS writer marks and paces its link."""
        tcpros = self.tcpros
        if tcpros is not None:
            tcpros.link_opened(conn, sock)

    def _connection_closed(self, conn: patches.DDSConnection) -> None:
        with self.lock:
            if self.connections.get(conn.endpoint_id) is conn:
                del self.connections[conn.endpoint_id]
                self.delegated.discard(conn.endpoint_id)
        self._refresh_writers()

    def _reached(self, conns: Any, dds: "DDSTopicWriter") -> Set[str]:
        """Reader GUIDs among ``conns`` that are there now: matched by our writer, or, for subscribers
        served by foreign writers, alive in DDS discovery."""
        matched = dds.matched_peers()
        if self._foreign is not None and self.delegated:
            alive = self._foreign[1]
            matched |= {c.peer_guid for c in conns if c.endpoint_id in self.delegated and alive(c.peer_guid)}
        return matched

    def _gate_dds(self) -> None:
        """Write to DDS only when a matched reader wants it: a ROS 2 (untagged) reader, or a micros_rt reader this
        publication serves over DDS. A micros_rt reader of this graph served over shared memory or TCPROS (its
        reader exists for ROS 2's sake) drops DDS samples of a writer its node did not negotiate with: without
        this, every message to a local SHM subscriber was also encoded and sent over loopback DDS, for nothing."""
        dds = self.dds
        if dds is None:
            return
        if self.latch or self._foreign is not None:
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
        """Drop DDS links whose reader went away, or that discovery never matched in time
        (an offer nobody follows up must not stay a connection forever), and SHM channels whose subscriber
        left (a SIGKILLed one's ports are reclaimed first); decide whether DDS readers want the samples."""
        if self.shm is not None:
            self.shm.housekeeping(now, self._shm_channel_gone)
        self._gate_dds()
        dds = self.dds
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
                _log.debug("micros_rt: topic %s: DDS subscriber %s is gone", self.topic, short(conn.endpoint_id))
            elif now - conn.created > UNMATCHED_READER_TIMEOUT:
                _housekeeping_log.warning(
                    (self.topic, "unmatched"),
                    f"topic {self.topic}: DDS subscriber {short(conn.endpoint_id)} was accepted but its reader "
                    f"{conn.peer_guid} never appeared in DDS discovery within {UNMATCHED_READER_TIMEOUT:.0f} s; "
                    f"dropped the connection (check both nodes' ROS_IP/CYCLONEDDS_URI and ROS_DOMAIN_ID)")
                self._expired[conn.peer_guid] = conn
                while len(self._expired) > MAX_PENDING_DDS_OFFERS:
                    self._expired.popitem(last=False)
            else:
                continue
            patches.remove_pseudo_connection(self.topic, conn, publisher=True)
            conn.close()
        # a real subscriber on a slow or lossy network can be discovered after the bound: take it back
        for guid in [g for g in self._expired if g in matched]:
            old = self._expired.pop(guid)
            if old.endpoint_id in self.connections:
                continue
            late = patches.DDSConnection(self.topic, old.endpoint_id, "o", old.info, peer_guid=guid,
                                        on_close=self._connection_closed)
            late.seen = True
            with self.lock:
                self.connections[old.endpoint_id] = late
            if patches.add_pseudo_connection(self.topic, late, publisher=True):
                _log.warning("micros_rt: topic %s: DDS subscriber %s was discovered late; connected again",
                             self.topic, short(old.endpoint_id))
            else:
                late.close()

    def ready_connections(self) -> int:
        """Subscribers a message published now reaches: TCPROS links, and DDS subscribers whose
        reader the writer has matched (negotiation precedes DDS discovery by a few milliseconds;
        counting those early would let a "wait for a subscriber, then publish" loop lose its first
        messages)."""
        tcpros = self.tcpros
        if tcpros is None:
            return 0
        with self.lock:
            conns = list(self.connections.values())
            n_shm = len(self.shm_links)
        n_tcp = max(tcpros.links() - len(conns) - n_shm, 0)
        if n_shm and self.shm is not None:
            n_tcp += self.shm.attached_count()
        if not conns or self.dds is None:
            return n_tcp
        matched = self._reached(conns, self.dds)
        return n_tcp + sum(1 for c in conns if c.peer_guid in matched)

    # -- data ----------------------------------------------------------------
    def publish(self, msg: Any) -> None:
        """Refuse a bad message before anything is sent on any transport, then send it on each."""
        if self.closed or not self.writers:
            raise rospy.ROSException(f"publish() to a closed topic {self.topic}")
        with self._publish_lock:  # one message at a time, in the same order on every transport
            try:
                # every writer prepares (serializes, may raise) before any sends; TCPROS, first, raises
                # inside its send before it writes anything
                prepared = [(w, w.prepare(msg)) for w in self.writers]
                for writer, data in prepared:
                    if data is None:
                        continue  # nobody to send to on that transport
                    t0 = time.monotonic()
                    try:
                        writer.send(data)
                    finally:
                        waited = time.monotonic() - t0
                        if waited > 0.001:
                            self.blocked_seconds += waited
                self.published += 1
            except (genpy.SerializationError, struct.error, TypeError, ValueError, AttributeError, OverflowError,
                    UnicodeError) as exc:
                raise rospy.ROSSerializationException(
                    f"topic {self.topic}: cannot serialize {type(msg).__name__}: {exc}") from exc

    def statistics(self) -> PublisherStatistics:
        shm_dropped = self.shm.dropped if self.shm is not None else 0
        return PublisherStatistics(published=self.published,
                                   dropped=sum(lane.dropped for lane in self.lanes) + shm_dropped,
                                   blocked_seconds=self.blocked_seconds,
                                   expired=sum(lane.expired for lane in self.lanes))

    def close(self) -> None:
        """Release the DDS links and writer and unregister from rospy (the registry calls this once)."""
        self.closed = True
        with self.lock:
            conns = list(self.connections.values()) + list(self.shm_links.values())
        for conn in conns:
            conn.close()
        shm, self.shm = self.shm, None
        if shm is not None:
            shm.close()
        self.dds, self.mirrors = None, ()
        senders, self.senders, self.writers = self.senders, (), ()
        for sender in reversed(senders):
            sender.close()  # a lane lets what it holds leave first, then closes its writer
        if self.tcpros is not None:
            try:
                self.tcpros.close()
            except Exception as exc:  # rospy at shutdown; the rest is released already
                _log.warning("micros_rt: topic %s: rospy could not unregister the publisher: %s", self.topic, exc)


class Publisher:
    """Returned by :meth:`NodeHandle.advertise`; rospy's Publisher API."""

    def __init__(self, pub: _Publication, registry: EndpointRegistry[_Publication]) -> None:
        self._pub: Optional[_Publication] = pub
        self._registry = registry
        self.resolved_name = pub.topic
        self.name = pub.topic
        self.data_class = pub.data_class
        self.type = pub.data_class._type
        self.md5sum = pub.data_class._md5sum

    @property
    def qos(self) -> AdvertiseQoSOptions:
        """The QoS this publisher's topic uses (after merging the YAML profile)."""
        if self._pub is None:
            raise rospy.ROSException("publisher is unregistered")
        return self._pub.options

    def publish(self, *args: Any, **kwds: Any) -> None:
        """Publish a message (or its fields), to DDS readers and TCPROS peers alike.

        Raises ``rospy.ROSSerializationException`` for a bad field value (nothing is sent then), and
        :class:`micros_rt.PublishTimeoutError` when a lossless topic (``queue_size=None``) stays blocked
        on a subscriber that does not keep up.
        """
        pub = self._pub
        if pub is None:
            raise rospy.ROSException("publish() to an unregistered() handle")
        if len(args) == 1 and not kwds and type(args[0]) is pub.data_class:
            pub.publish(args[0])  # the common case, without rospy's argument parsing
        else:
            pub.publish(rospy.topics.args_kwds_to_message(pub.data_class, args, kwds))

    def get_num_connections(self) -> int:
        """Subscribers this topic reaches now, over TCPROS and DDS (DDS ones once discovery matched them)."""
        return 0 if self._pub is None else self._pub.ready_connections()

    def get_dds_connections(self) -> int:
        return 0 if self._pub is None else len(self._pub.connections)

    def get_delegated_dds_connections(self) -> int:
        """DDS subscribers served by the foreign writers of :meth:`delegate_dds`, not by this node."""
        pub = self._pub
        if pub is None:
            return 0
        with pub.lock:
            return len(pub.delegated)

    def delegate_dds(self, source: ForeignSource, alive: ReaderAlive) -> None:
        """Serve this topic's micros_rt subscribers with another graph's writers when they can take them.

        For a program that republishes what arrives over DDS from another ROS graph's relay (an importing
        relay): ``source()`` names those writers now (None: none), ``alive(guid)`` says whether a reader is
        still in DDS discovery. A subscriber whose offer those writers can serve (same DDS topic and domain,
        compatible QoS) is answered with them and reads them straight, and keeps reading their successors
        (a restarted relay); any other is served by this node's own writer, which sends only while such a
        subscriber exists. Writers of another topic (``ForeignWriters.topic``, a renamed import) serve the
        subscribers that open a reader there (micros_rt's do). TCPROS subscribers are unaffected."""
        if self._pub is None:
            raise rospy.ROSException("publisher is unregistered")
        self._pub.delegate_dds(source, alive)

    def statistics(self) -> PublisherStatistics:
        """Counters of this topic's publication (shared by the Publishers of the topic in this node)."""
        if self._pub is None:
            raise rospy.ROSException("publisher is unregistered")
        return self._pub.statistics()

    def unregister(self) -> None:
        """Stop publishing; the topic's writer goes when its last Publisher does. Harmless twice."""
        pub, self._pub = self._pub, None
        if pub is not None:
            self._registry.release(pub)

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.unregister()

    close = unregister
