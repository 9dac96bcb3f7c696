"""The DDS side of a subscription: its offer (the reader's GUID, or a lazy offer with ROS 2 visibility off),
the readers it opens (the topic's, a latched one, another graph's relay topic it follows) and the writers a
publisher's answer names, accepted into its exactly-once table (:mod:`.exactly_once`).

Its readers are pulled: the subscription's delivery thread drains this side (:meth:`DDSSubscription.drain`),
which takes their samples, holds or drops them per writer, keeps the newest ``queue_size``, decodes what it
delivers and hands it to the subscription's one admission path and callbacks. Importing this module imports no
DDS library."""

from __future__ import annotations

import collections
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Deque, Dict, List, Optional, Protocol, Set, Tuple

from ...exceptions import MicrosRtError
from ...log import nonblocking_logger
from ...negotiation import DDS
from ...qos import UNBOUNDED_QUEUE_DEPTH, describe_incompatible_policy
from ..base import EndpointSpec, TransportReader
from ..negotiated import SubscriptionHost, SubscriptionSide
from ..links import PseudoLink, add_link, remove_link
from .exactly_once import DELIVER, HOLD, Accepted, WriterState, WriterTable
from .offer import DDSAnswer, DDSOffer, DDSOpenFirst

if TYPE_CHECKING:
    from .backend import DDSBackend, DDSTopicReader

__all__ = ["DDSSubscription", "DDSSubscriptionHost"]

_log = nonblocking_logger("rosout.micros_rt")
_RETAKE_SECONDS = 0.005  # with a bounded queue, take new samples at least this often between callbacks
#: seconds an accepted publisher's writer may stay undiscovered before its link is dropped
_UNDISCOVERED_SECONDS = 30.0


class DDSSubscriptionHost(SubscriptionHost, Protocol):
    """What the DDS side needs beyond every side's host: the subscription's graph, counters, admission and
    delivery, and its delivery thread's inbox for the readers' conditions."""

    graph: str
    received: int
    dropped_queue_full: int
    malformed: int
    burst_dropped: int

    def attach_reader(self, reader: "DDSTopicReader") -> None:
        """Wake the delivery thread on ``reader``'s condition when its inbox can."""

    def reader_wakes(self) -> bool:
        """True when a reader must wake the delivery thread per sample (its inbox waits on no reader condition)."""

    def drain_me(self, side: SubscriptionSide) -> None:
        """Let the delivery thread drain ``side`` (its pulled readers) from now on."""

    def matches_changed(self) -> None:
        """A writer matched or went (Cyclone's thread): housekeeping soon."""

    def admit(self, reader: TransportReader, source_ns: int, qos: Optional[Any], *, sent_ns: int = 0) -> bool:
        """The subscription's one admission path (the enforced options; what is dropped is counted there)."""

    def deliver(self, msg: Any, source_ns: Optional[int], budget: float) -> None:
        """Hand one admitted message to the callbacks."""

    def pushed_pending(self) -> bool:
        """Messages waiting in the subscription's pushed readers."""


class DDSSubscription(SubscriptionSide):
    """A subscription's DDS readers and accepted writers (see the module's text)."""

    protocol = DDS
    words = "DDS"

    def __init__(self, host: DDSSubscriptionHost, *, backend: "Optional[DDSBackend]",
                 lazy: "Optional[Callable[[], Optional[DDSBackend]]]" = None) -> None:
        super().__init__(host)
        self.dds_host = host
        self.backend = backend
        #: with ROS 2 visibility off: opens the process's DDS back end when a first publisher would take DDS
        self._lazy = lazy
        self._opening = threading.Lock()
        self.reader: "Optional[DDSTopicReader]" = None
        self.tl_reader: "Optional[DDSTopicReader]" = None
        self._followed: Dict[Tuple[str, bool], "DDSTopicReader"] = {}  # (topic, latched) -> reader (_follow)
        #: the exactly-once table: per DDS writer, whether its samples are delivered, held or dropped
        self.writers = WriterTable(host.graph, host.depth or UNBOUNDED_QUEUE_DEPTH)
        #: the pulled readers the delivery thread takes from; the first decodes for all
        self.readers: Tuple["DDSTopicReader", ...] = ()
        self._duplicates = False  # two readers may see one sample (a latched reader beside the topic's)
        self.queue: Deque[Tuple[bytes, Any, WriterState]] = collections.deque()
        self.incompatible_reported: Set[int] = set()
        if backend is not None:
            try:
                self.reader = self._open_reader(latched=False)
            except MicrosRtError as exc:
                _log.warning("micros_rt: topic %s will use TCPROS only: %s", host.topic, exc)

    def _open_reader(self, *, latched: bool, topic: Optional[str] = None) -> "DDSTopicReader":
        """A DDS reader of the subscription's topic (or of ``topic``, another name of its data) feeding the
        delivery thread."""
        assert self.backend is not None
        host = self.dds_host
        spec = EndpointSpec(topic or host.topic, host.data_class, host.queue_size, latched, host.tag)
        reader = self.backend.open_reader(spec, host.options, host.matches_changed, self._incompatible,
                                          wake_on_data=host.reader_wakes())
        host.attach_reader(reader)
        first = not self.readers
        self.readers = self.readers + (reader,)
        self._duplicates = self._duplicates or (latched and topic is None)
        if first:
            host.drain_me(self)
        return reader

    def _incompatible(self, policy: int) -> None:
        # Cyclone thread: only log, never block. A ROS 2 (or foreign) writer whose QoS cannot match
        # ours would otherwise be silence.
        if policy not in self.incompatible_reported:
            self.incompatible_reported.add(policy)
            _log.warning("micros_rt: %s", describe_incompatible_policy(policy, topic=self.host.topic,
                                                                        side="subscriber"))

    # -- negotiation (rospy's connect threads) ----------------------------
    def offer(self, held: str) -> Optional[List[Any]]:
        host, reader, dds = self.dds_host, self.reader, self.backend
        if reader is None and self._lazy is not None:
            from .participant import domain_id_from_env

            return DDSOffer(domain=domain_id_from_env(), topic="", type_name="", md5=host.data_class._md5sum,
                            qos=host.effective, reader="", participant="", graph=self.writers.graph,
                            lazy=True).to_xmlrpc()
        if reader is not None and dds is not None:
            return DDSOffer(domain=dds.domain_id, topic=reader.dds_topic, type_name=reader.dds_type.type_name,
                            md5=host.data_class._md5sum, qos=host.effective, reader=reader.guid,
                            participant=dds.participant.guid, graph=self.writers.graph, follow=True).to_xmlrpc()
        return None

    def read_answer(self, params: Any, source: str) -> DDSAnswer:
        return DDSAnswer.from_xmlrpc(params, source=source)

    def peer_of(self, answer: Any) -> str:
        return str(answer.writer)

    def asks_open_first(self, entry: List[Any]) -> bool:
        return DDSOpenFirst.is_one(entry)

    def open_first(self) -> bool:
        """With ROS 2 visibility off: open the DDS reader now (a publisher would take DDS; rospy's connect
        thread). True when there is one."""
        with self._opening:
            if self.reader is None and self._lazy is not None and not self.host.closed:
                backend = self._lazy()
                self._lazy = None
                if backend is not None:
                    self.backend = backend
                    try:
                        self.reader = self._open_reader(latched=False)
                        _log.info("micros_rt: topic %s: DDS reader made",
                                  self.host.topic)
                    except MicrosRtError as exc:
                        _log.warning("micros_rt: topic %s will use TCPROS only: %s", self.host.topic, exc)
        return self.reader is not None

    def connect(self, pub_uri: str, answer: Any) -> Tuple[int, str, int]:
        host = self.dds_host
        if host.closed:
            return 0, "subscriber closed", 0
        if answer.latch:
            with host.lock:  # two latched publishers connecting at once must not make two readers
                if self.tl_reader is None and self.backend is not None:
                    try:
                        self.tl_reader = self._open_reader(latched=True)
                    except MicrosRtError as exc:
                        _log.warning("micros_rt: topic %s: no latched message over DDS: %s", host.topic, exc)
        dds_topic = self.reader.dds_topic if self.reader else host.topic
        if answer.via and answer.topic and answer.topic != host.topic:
            # the relay's writers write the topic under its outside name: read it there too
            dds_topic = self._follow(answer.topic, answer.latch)
            if not dds_topic:
                return 0, f"cannot read {answer.topic} over DDS", 0
        source = (f"straight from the writers of graph {answer.via}'s relay (now {answer.writer}), no hop through "
                  f"{answer.node or pub_uri}") if answer.via else f"from writer {answer.writer}"
        conn = PseudoLink(host.topic, pub_uri, "i", f"DDS connection on topic {dds_topic} {source}",
                                    peer_guid=answer.writer, on_close=self.writers.connection_closed,
                                    callerid_pub=answer.node)
        accepted = Accepted(pub_uri, answer.node, answer.latch, conn)
        self.writers.accept(answer.writer, accepted, answer.qos)
        if answer.via:
            self.writers.delegate(answer.via, accepted, answer.qos)
        host.raise_priority(answer.qos)
        if not add_link(host.topic, conn, publisher=False):
            conn.close()
            return 0, "subscriber closed", 0
        _log.debug("micros_rt: topic %s: receiving from %s over DDS", host.topic, pub_uri)
        host.wake()
        return 1, f"Connected topic[{host.topic}] over DDS", 0

    def _follow(self, topic: str, latched: bool) -> str:
        """A reader of ``topic`` (another ROS name of this subscription's data, a relay's outside name) for
        delegated writers that write there; opened once, closed with the subscription. Its DDS topic name,
        or "" when DDS refuses it (the publisher then serves this subscriber over TCPROS)."""
        host = self.host
        with host.lock:
            reader = self._followed.get((topic, latched))
            if reader is None and self.backend is not None and not host.closed:
                try:
                    reader = self._open_reader(latched=latched, topic=topic)
                except MicrosRtError as exc:
                    _log.warning("micros_rt: topic %s: cannot read %s over DDS: %s", host.topic, topic, exc)
                    return ""
                self._followed[(topic, latched)] = reader
        return reader.dds_topic if reader is not None else ""

    # -- the delivery thread -------------------------------------------------
    def drain(self, limit: int) -> bool:
        """Take what the readers have and deliver it, the newest ``queue_size`` kept; True when more may wait."""
        more = False
        for reader in self.readers:
            batch = reader.take(limit)
            if batch:
                more = more or len(batch) >= limit
                self._admit(reader, batch)
        queue = self.queue
        if queue:
            bounded = self.host.depth is not None
            last_take = time.monotonic() if bounded else 0.0
            while queue:
                data, info, state = queue.popleft()
                self._deliver(data, info, state)
                if bounded and time.monotonic() - last_take > _RETAKE_SECONDS:
                    break  # take again: the newest queue_size are what ROS delivers
        return more or bool(queue)

    def _admit(self, reader: "DDSTopicReader", batch: Any) -> None:
        """Exactly-once and queue_size: each valid sample is queued, held or dropped (and counted)."""
        writers, queue, host = self.writers, self.queue, self.dds_host
        depth = host.depth
        two_readers = self._duplicates
        for data, info in batch:
            if not info.valid_data:
                continue
            state = writers.for_handle(reader, info.publication_handle)
            if state is None:
                continue
            verdict = writers.decide(state)
            if verdict != DELIVER:
                if verdict == HOLD:
                    writers.hold(state, time.monotonic(), data, info)
                continue
            acc = state.accepted
            if acc is not None and not acc.conn.seen:
                acc.conn.seen = True  # it delivered data, so it was matched (housekeeping may not have seen it)
            if state.held:
                self.tick(time.monotonic())  # what it sent before the answer goes first
            if two_readers:
                if info.source_timestamp <= state.last_ts:
                    continue  # the same sample through the other reader
                state.last_ts = info.source_timestamp
            host.received += 1
            queue.append((data, info, state))
            if depth is not None and len(queue) > depth:
                queue.popleft()
                host.dropped_queue_full += 1
                host.burst_dropped += 1

    def tick(self, now: float) -> None:
        """Deliver what writers held until their negotiation answered (each wake of the delivery thread)."""
        if not self.writers.holding:
            return
        for state in self.writers.releasable(now):
            held, state.held = state.held, collections.deque()
            for _t, data, info in held:
                self.dds_host.received += 1
                self._deliver(data, info, state)

    def _deliver(self, data: bytes, info: Any, state: WriterState) -> None:
        host, qos = self.dds_host, state.qos
        reader = self.readers[0]
        if not host.admit(reader, info.source_timestamp, qos, sent_ns=info.source_timestamp):
            return
        if not state.skew.done:
            self._check_clock_skew(state, time.time_ns() - info.source_timestamp, time.monotonic())
        try:
            msg = reader.decode(data)
        except ValueError as exc:
            self._malformed(state, exc)
            return
        head = msg.header if msg._has_header else msg if msg._type == "std_msgs/Header" else None
        if head is not None:
            # ROS 2 Header has no seq: regenerate it per publisher (DDS writer), 1, 2, ... as rospy counts
            state.header_seq += 1
            head.seq = state.header_seq
        header = state.conn_header
        if header is None:
            # one dict per writer, shared by its messages as rospy shares one per connection; callerid is
            # the publisher's node name, as in rospy's TCPROS header
            acc = state.accepted
            data_class = host.data_class
            header = {"callerid": (acc.node or acc.conn.endpoint_id) if acc else state.guid, "topic": host.topic,
                      "type": data_class._type, "md5sum": data_class._md5sum, "transport": DDS}
            if acc is not None:
                state.conn_header = header
        msg._connection_header = header
        if state.accepted is not None and state.accepted.latch:
            state.latched = msg
        host.deliver(msg, info.source_timestamp, qos.latency_budget if qos is not None else 0.0)

    def _malformed(self, state: WriterState, exc: Exception) -> None:
        # once per writer in words, then counted: a broken peer must not flood the log
        state.malformed += 1
        self.dds_host.malformed += 1
        if state.malformed == 1:
            _log.warning("micros_rt: topic %s: dropped a malformed DDS sample from writer %s (%s); is its type "
                         "really %s? Further malformed samples from it are counted, not logged",
                         self.host.topic, state.guid, str(exc)[:200], self.host.data_class._type)

    def _check_clock_skew(self, state: WriterState, age_ns: int, now: float) -> None:
        skew = state.skew.observe(age_ns, now)
        if skew is None:
            return
        topic = self.host.topic
        acc = state.accepted
        who = acc.pub_uri if acc else state.guid
        node = (state.tag or {}).get("node") or (acc.node if acc else "") or "a non-micros_rt node"
        effects = ("Subscribers ordered by sending timestamp drop its samples in favour of other publishers', "
                   "and msg_valid_period expires them")
        if skew < 0:
            _log.warning("micros_rt: topic %s: the clock of publisher %s (%s, writer %s) runs %.1f s ahead of "
                         "this node's clock (its samples arrive stamped %.1f s in the future). %s; synchronise "
                         "the clocks (NTP/chrony)", topic, who, node, state.guid, -skew, -skew, effects)
            return
        # a sample stamped in the past is a clock behind or a sample that waited: a whole window of them
        # (ClockSkewCheck) is more likely the clock, but a node starved of CPU for that long looks the same
        _log.warning("micros_rt: topic %s: every sample of publisher %s (%s, writer %s) in its first %.1f s "
                     "arrived stamped at least %.1f s in the past: its clock runs %.1f s behind this node's "
                     "clock, or its samples waited that long on the way (this node or the network "
                     "overloaded). %s; if the clocks differ, synchronise them (NTP/chrony)", topic, who,
                     node, state.guid, state.skew.window, skew, skew, effects)

    def housekeeping(self, now: float) -> None:
        """Drop links of DDS publishers whose writer vanished (a restart then reconnects) and their state."""
        if not self.readers:
            return
        matched: Set[str] = set()
        for reader in self.readers:
            matched |= reader.matched_writers()
        for state in self.writers.accepted_states():
            acc = state.accepted
            if acc is None:
                continue
            conn = acc.conn
            if state.guid in matched:
                conn.seen = True
                continue
            if self.writers.is_delegated(conn):
                # one of another graph's relay writers went (that relay restarted): its successor is taken
                # as it comes; the link to the delegating publisher lasts as long as that publisher
                if conn.seen or now - conn.created > _UNDISCOVERED_SECONDS:
                    self.writers.forget_writer(state)
                continue
            if not conn.seen and now - conn.created <= _UNDISCOVERED_SECONDS:
                continue
            if not conn.seen:
                _log.warning("micros_rt: topic %s: publisher %s accepted DDS but its writer was never discovered "
                             "in 30 s; check both nodes' network (ROS_IP, CYCLONEDDS_URI)", self.host.topic,
                             acc.pub_uri)
            remove_link(self.host.topic, conn, publisher=False)
            conn.close()
        if self.queue or self.dds_host.pushed_pending():
            return  # samples of a gone writer still to deliver: prune next time
        self.writers.prune(matched)

    def pending(self) -> bool:
        return bool(self.queue)

    def latched(self) -> List[Any]:
        return [s.latched for s in self.writers.accepted_states() if s.latched is not None]

    def kept_writers(self) -> int:
        return len(self.writers)

    def has_reader(self) -> bool:
        return bool(self.readers)

    def close(self) -> None:
        """After the delivery thread stopped: the accepted writers' links and the readers."""
        for state in self.writers.accepted_states():
            if state.accepted is not None:
                state.accepted.conn.close()
        self.reader = self.tl_reader = None
        readers, self.readers = self.readers, ()
        for reader in readers:
            reader.close()
