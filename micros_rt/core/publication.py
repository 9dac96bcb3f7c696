"""A micros_rt publication: per topic and process, the TCPROS writer (rospy's publisher: master registration,
stock peers), the negotiated transports' sides (shared memory, DDS: :mod:`micros_rt.transports.negotiated`)
and the writers a YAML profile mirrors every message to (MQTT)."""

from __future__ import annotations

import collections
import struct
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional, Sequence, Tuple, Type

import genpy
import rospy
import rospy.topics

from ..negotiation import OfferJudge, Verdict, remember_verdict
from ..negotiation import protocol as names
from ..qos import AdvertiseQoSOptions
from ..transports.base import EndpointSpec, ProfileBackend, TransportWriter
from ..transports.negotiated import PublicationSide
from ..transports.tcpros.patches import short
from ..transports.tcpros.writer import TcprosWriter
from ..log import nonblocking_logger
from .send_queue import SendQueue, sender_for
from .registry import EndpointRegistry
from .stats import PublisherStatistics

if TYPE_CHECKING:
    from ..transports.pacing import LinkPacer

__all__ = ["Publisher"]

_log = nonblocking_logger("rosout.micros_rt")

#: how a node makes one negotiated transport's side of a publication (the publication is its host), in the
#: order of preference (:mod:`.negotiated`)
SideFactory = Callable[["_Publication"], PublicationSide]


class _Publication:
    """Per topic and process: the TCPROS writer, the negotiated sides, the mirrors. Owned by the registry."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int], latch: bool,
                 options: AdvertiseQoSOptions, *, tag: Dict[str, str], sides: Sequence[SideFactory] = (),
                 extra: Tuple[ProfileBackend, ...] = (), pacer: "Optional[LinkPacer]" = None) -> None:
        self.topic = topic
        self.tag = tag
        self._pacer = pacer
        self.data_class = data_class
        self.latch = latch
        self.options = options
        self.queue_size = queue_size
        self.lock = threading.Lock()
        # the last verdict per subscriber caller id, for `micros-rt topic info` (bounded)
        self.verdicts: "collections.OrderedDict[str, Verdict]" = collections.OrderedDict()
        self.published = 0
        self.blocked_seconds = 0.0
        self.closed = False
        self._publish_lock = threading.Lock()
        self.tcpros: Optional[TcprosWriter] = None
        #: the negotiated transports, in preference order, by protocol name
        self.sides: Dict[str, PublicationSide] = {}
        for make in sides:
            side = make(self)
            self.sides[side.protocol] = side
        # writers of the transports the YAML profile attaches to this topic (MQTT): every message is mirrored
        spec = EndpointSpec(topic, data_class, queue_size, latch, tag)
        self.mirrors: Tuple[TransportWriter, ...] = tuple(
            w for w in (b.open_writer(spec, options) for b in extra) if w is not None)
        #: what publish() sends through, per writer: a send queue in front of one that can say "no room now"
        self._senders: List[Tuple[TransportWriter, TransportWriter]] = []  # (writer, its sender)
        #: every writer publish() uses now, in sending order: TCPROS first (rospy serializes inside its send and
        #: raises before writing), then the negotiated sides' senders, then the mirrors'
        self.writers: Tuple[TransportWriter, ...] = ()

    # -- the host of the negotiated sides -------------------------------------
    def remember(self, subscriber: str, verdict: Verdict) -> None:
        with self.lock:
            remember_verdict(self.verdicts, short(subscriber, 256), verdict)

    def latched_message(self) -> Optional[Any]:
        return self.tcpros.latched() if self.tcpros is not None else None

    def _sender(self, writer: TransportWriter) -> TransportWriter:
        """``writer``'s sender, made once: one topic's back-pressure never holds another topic's publish(), and a
        KEEP_LAST publish() never waits (as rospy's)."""
        with self.lock:
            for known, sender in self._senders:
                if known is writer:
                    return sender
            sender = sender_for(writer, topic=self.topic, queue_size=self.queue_size, options=self.options)
            self._senders.append((writer, sender))
            return sender

    def writers_changed(self) -> None:
        """The writers ``publish`` uses: TCPROS, each negotiated side's that sends now, the mirrors."""
        if self.tcpros is None or self.closed:
            return
        negotiated = tuple(self._sender(s.writer) for s in self.sides.values()
                           if s.writer is not None and s.sending())
        self.writers = (self.tcpros,) + negotiated + tuple(self._sender(w) for w in self.mirrors)

    def start(self) -> None:
        self.tcpros = TcprosWriter(self.topic, self.data_class, self.queue_size, self.latch,
                                   pseudo_links=lambda: sum(s.pseudo_links() for s in self.sides.values()),
                                   priority=self.options.transport_priority, pacer=self._pacer)
        self.writers_changed()

    def delegate(self, protocol: str, source: Callable[[], Any], alive: Callable[[str], bool]) -> None:
        side = self.sides.get(protocol)
        if side is None:
            raise rospy.ROSException(f"topic {self.topic} has no {protocol} side to delegate (transport_hints)")
        side.delegate(source, alive)

    # -- negotiation (XML-RPC threads) -------------------------------------
    def negotiated_transports(self, subscriber: str) -> Dict[str, OfferJudge]:
        """What ``requestTopic`` may negotiate for this topic with ``subscriber``: each side's, judged there."""
        negotiated: Dict[str, OfferJudge] = {}
        for protocol, side in self.sides.items():
            transport = side.negotiated(subscriber)
            if transport is not None:
                negotiated[protocol] = transport
        return negotiated

    def on_tcpros_connection(self, conn: Any, sock: Any) -> None:
        """A TCPROS subscriber connected (rospy's thread): the TCPROS writer marks and paces its link."""
        tcpros = self.tcpros
        if tcpros is not None:
            tcpros.link_opened(conn, sock)

    def housekeeping(self, now: float) -> None:
        """Each side drops links whose subscriber went away (the node's housekeeping thread)."""
        for side in self.sides.values():
            side.housekeeping(now)

    def ready_connections(self) -> int:
        """Subscribers a message published now reaches: TCPROS links, and each side's reached subscribers."""
        tcpros = self.tcpros
        if tcpros is None:
            return 0
        sides = self.sides.values()
        return max(tcpros.links() - sum(s.pseudo_links() for s in sides), 0) + sum(s.reached() for s in sides)

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

    def send_queues(self) -> List[SendQueue]:
        """The send queues in front of this topic's writers that can say "no room now" (DDS)."""
        with self.lock:
            return [s for _, s in self._senders if isinstance(s, SendQueue)]

    def statistics(self) -> PublisherStatistics:
        queues = self.send_queues()
        return PublisherStatistics(published=self.published,
                                   dropped=sum(q.dropped for q in queues) + sum(s.dropped() for s in self.sides.values()),
                                   blocked_seconds=self.blocked_seconds,
                                   expired=sum(q.expired for q in queues),
                                   refused_offers=sum(s.refused()[0] for s in self.sides.values()),
                                   unused_links=sum(s.refused()[1] for s in self.sides.values()))

    def close(self) -> None:
        """Release the links and writers and unregister from rospy (the registry calls this once)."""
        self.closed = True
        writers = [s.writer for s in self.sides.values() if s.writer is not None] + list(self.mirrors)
        for side in self.sides.values():
            side.close()
        with self.lock:
            pairs, self._senders = self._senders, []
        self.writers, self.mirrors = (), ()
        for _writer, sender in reversed(pairs):
            sender.close()  # a send queue lets what it holds leave first, then closes its writer
        for writer in writers:  # never sent through (the publication did not start)
            if not any(writer is w for w, _ in pairs):
                writer.close()
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

    def reaches(self, node: str) -> bool:
        """Whether a message published now reaches the subscriber node ``node`` (its caller id, as the master
        lists it): its TCPROS link is up, its shared-memory port attached or its DDS reader matched. Waiting for
        ``get_num_connections()`` to reach a count can be fooled by another subscriber connecting first."""
        tcpros = None if self._pub is None else self._pub.tcpros
        return tcpros is not None and tcpros.reaches(node)

    def get_dds_connections(self) -> int:
        side = None if self._pub is None else self._pub.sides.get(names.DDS)
        return 0 if side is None else side.pseudo_links()

    def get_delegated_dds_connections(self) -> int:
        """DDS subscribers served by the foreign writers of :meth:`delegate_dds`, not by this node."""
        side = None if self._pub is None else self._pub.sides.get(names.DDS)
        return 0 if side is None else side.delegated_links()

    def delegate_dds(self, source: Callable[[], Any], alive: Callable[[str], bool]) -> None:
        """Serve this topic's micros_rt subscribers with another graph's writers when they can take them.

        For a program that republishes what arrives over DDS from another ROS graph's relay (a relay that
        brings a topic in): ``source()`` names those writers now (a :class:`micros_rt.ForeignWriters`; None: none), ``alive(guid)`` says whether a reader is
        still in DDS discovery. A subscriber whose offer those writers can serve (same DDS topic and domain,
        compatible QoS) is answered with them and reads them straight, and keeps reading their successors
        (a restarted relay); any other is served by this node's own writer, which sends only while such a
        subscriber exists. Writers of another topic (``ForeignWriters.topic``, a renamed import) serve the
        subscribers that open a reader there (micros_rt's do). TCPROS subscribers are unaffected."""
        if self._pub is None:
            raise rospy.ROSException("publisher is unregistered")
        self._pub.delegate(names.DDS, source, alive)

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
