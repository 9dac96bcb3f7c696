"""A micros_rt subscription: per topic and process, the TCPROS reader (rospy's subscriber: master
registration, stock peers), the negotiated transports' sides (shared memory, DDS:
:mod:`micros_rt.transports.negotiated`), the readers they and the profile's feeds (MQTT) hand messages to, and
the delivery thread that runs the callbacks.

The concerns live apart: waking (:mod:`.delivery`), exactly-once per DDS writer
(:mod:`micros_rt.transports.dds.exactly_once`), what the subscriber enforces (:mod:`micros_rt.qos.enforcement`),
counters and latency (:mod:`.stats`). This module joins them: samples in, callbacks out, every message either
delivered or counted in one drop counter.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Deque, Dict, List, Mapping, Optional, Set, Tuple, Type

import genpy
import rospy

from ..transports.tcpros import patches
from ..transports.tcpros.reader import TcprosReader
from ..transports.links import remove_link
from . import threadprio
from .delivery import Inbox
from .registry import EndpointRegistry
from .stats import LatencyStats, SubscriberStatistics
from ..transports.dds.exactly_once import DELIVER, HOLD, WriterState, WriterTable
from ..transports.base import (SOURCE_ORDER, TIME_FILTER, EndpointSpec, Feed, ProfileBackend, PushInfo, PushReader,
                               ReaderBackend, TransportReader)
from ..transports.negotiated import SubscriptionSide
from ..negotiation import TCPROS, TransportHints
from ..qos import (
    UNBOUNDED_QUEUE_DEPTH,
    AdvertiseQoSOptions,
    DeadlineMissed,
    DeadlineMonitor,
    SourceOrder,
    SubscribeQoSOptions,
    TimeFilter,
    TransportPriority,
    describe_incompatible_policy,
    is_expired,
    is_lossless,
)
from ..log import nonblocking_logger

if TYPE_CHECKING:
    from ..transports.dds.backend import DDSBackend

__all__ = ["Subscriber", "DeadlineMissed", "LatencyStats"]

_log = nonblocking_logger("rosout.micros_rt")
_TAKE_BATCH = 256
_RETAKE_SECONDS = 0.005  # with a bounded queue, take new samples at least this often between callbacks

#: how a node makes one negotiated transport's side of a subscription (the subscription is its host)
SubscriptionSideFactory = Callable[["_Subscription"], SubscriptionSide]


class _Subscription:
    """Per topic and process: the TCPROS reader, the negotiated sides, the readers they feed and the delivery
    thread."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                 options: Optional[SubscribeQoSOptions], hints: TransportHints, *,
                 dds: "Optional[DDSBackend]", tag: Dict[str, str], graph: str,
                 sides: Mapping[str, SubscriptionSideFactory] = {}, extra: Tuple[ProfileBackend, ...] = (),
                 lifespan: float = math.inf) -> None:
        self.topic = topic
        #: the subscriber's own msg_valid_period (seconds): a message older than this by its source stamp is
        #: dropped (``dropped_expired``) whatever its publisher offers; the shorter of the two applies
        self.lifespan = lifespan
        self.data_class = data_class
        self.queue_size = queue_size
        self.options = options
        self.effective = options or SubscribeQoSOptions(ordered_by_sending_timestamp=False)
        self.hints = hints
        self.tag = tag
        # the newest `depth` are kept, as in ROS; None: nothing dropped (rospy's queue_size=None)
        self.depth: Optional[int] = None if is_lossless(queue_size) else queue_size
        # replaced, never mutated: the delivery thread iterates it without a copy or a lock
        self.callbacks: Tuple[Tuple[Callable[..., None], Any], ...] = ()
        self.lock = threading.Lock()
        self.closed = False
        self.stats = LatencyStats()
        self.received = self.delivered = self.dropped_queue_full = self.dropped_expired = 0
        self.dropped_filtered = self.dropped_out_of_order = self.malformed = 0
        self._burst_dropped = 0
        self.queue: Deque[Tuple[bytes, Any, WriterState]] = collections.deque()
        self.time_filter = TimeFilter(self.effective.time_filter_duration)
        self.source_order = SourceOrder(self.effective.ordered_by_sending_timestamp)
        self.deadline = DeadlineMonitor(self.effective.deadline, start=time.monotonic())
        self.writers = WriterTable(graph, self.depth or UNBOUNDED_QUEUE_DEPTH)
        self.incompatible_reported: Set[int] = set()
        self._housekeeping_due = False
        # the highest transport priority of the DDS publishers received from; the delivery thread takes it
        # on (core/threadprio.py: its nice value, the interpreter's switch interval for HIGH)
        self.priority: Optional[TransportPriority] = None
        self._thread_priority: Optional[TransportPriority] = None
        self._high_entered = False
        #: the process's DDS back end when the subscription opens its DDS reader at once (None: not, or lazily)
        self.dds = dds = dds if hints.allows_dds else None
        # With shared memory, the delivery thread waits on an iceoryx2 wait set (its SHM links' listeners: one
        # thread wake per message), and DDS readers wake it per sample from Cyclone's thread; else on Cyclone's.
        from ..transports import shm

        self.inbox = Inbox(None if dds is None or (hints.allows_shm and shm.unavailable_reason() is None)
                           else dds.participant)
        #: pulled readers (DDS), taken by the delivery thread; the first decodes for all
        self.readers: Tuple[ReaderBackend, ...] = ()
        self._duplicates = False  # two readers may see one sample (a latched reader beside the topic's)
        self._polled_inlet: Optional[PushReader] = None  # the pushed reader of links the delivery thread polls
        #: the negotiated transports the hints allow, by protocol name (each its side of the subscription)
        self.sides: Dict[str, SubscriptionSide] = {
            protocol: make(self) for protocol, make in sides.items() if protocol in hints.protocols}
        if not hints.allows_tcp and all(side.offer("") is None for side in self.sides.values()):
            _log.warning("micros_rt: topic %s: TransportHints allow only %s, and none is available here; "
                         "nothing will be received", topic, "/".join(hints.protocols))
        self.thread = threading.Thread(target=self._run, name=f"micros_rt delivery {topic}", daemon=True)
        self.tcpros: Optional[TcprosReader] = None
        # pushed readers: TCPROS (rospy's receive thread per connection waits for room: back-pressure to
        # that link, as rospy's own callback queue) and one per profile feed (MQTT: paho's network thread
        # is shared by every MQTT topic of the process, so it never waits; the oldest is dropped, counted)
        self.tcp_in = PushReader(TCPROS, self.depth or UNBOUNDED_QUEUE_DEPTH, self.inbox.wake, blocking=True,
                                 links=self._tcpros_links)
        self.pushed: Tuple[PushReader, ...] = (self.tcp_in,) + tuple(r for side in self.sides.values()
                                                                      for r in side.pushed())
        self._pushed_dropped = 0  # drops of non-blocking pushed readers already reported in a burst
        self._extra = extra
        self.feeds: Tuple[Feed, ...] = ()

    def start(self) -> None:
        """Start delivering and register with rospy (which triggers the negotiation: the reader exists)."""
        self.thread.start()
        self.tcpros = TcprosReader(self.topic, self.data_class, self.tcp_in.put, self.queue_size)
        # fed by the transports the YAML profile attaches to this topic (MQTT), each through a pushed
        # reader of its own into the same admission path (time filter, deadline, latency, counters)
        spec = EndpointSpec(self.topic, self.data_class, self.queue_size, False, self.tag)
        feeds: List[Feed] = []
        for backend in self._extra:
            inlet = PushReader("feed", self.depth, self.inbox.wake, blocking=False)
            feed = backend.open_feed(spec, self.options, inlet.put)
            if feed is not None:
                inlet.protocol = feed.protocol
                inlet.links = feed.transports
                feeds.append(feed)
                self.pushed = self.pushed + (inlet,)
        self.feeds = tuple(feeds)

    def _tcpros_links(self) -> Dict[str, str]:
        tcpros = self.tcpros
        return {} if tcpros is None else tcpros.transports()

    # -- the host of the negotiated sides -----------------------------------
    def add_reader(self, reader: ReaderBackend, *, duplicate: bool) -> None:
        self.inbox.attach(reader)
        self.readers = self.readers + (reader,)
        self._duplicates = self._duplicates or duplicate

    def reader_wakes(self) -> bool:
        # a delivery thread that waits on no Cyclone wait set (a reader opened later) is woken per sample
        return self.inbox.waitset is None

    def matches_changed(self) -> None:
        # Cyclone thread: a writer matched or went (lease expired, deleted): look at once, not at the
        # next housekeeping round, so a dead publisher leaves the connections within the lease
        self._housekeeping_due = True
        self.inbox.wake()

    def incompatible(self, policy: int) -> None:
        # Cyclone thread: only log, never block. A ROS 2 (or foreign) writer whose QoS cannot match
        # ours would otherwise be silence.
        if policy not in self.incompatible_reported:
            self.incompatible_reported.add(policy)
            _log.warning("micros_rt: %s", describe_incompatible_policy(policy, topic=self.topic, side="subscriber"))

    def raise_priority(self, qos: Optional[AdvertiseQoSOptions]) -> None:
        if qos is not None and (self.priority is None or qos.transport_priority > self.priority):
            # taken on by the delivery thread, at its next wake
            self.priority = TransportPriority(qos.transport_priority)

    def wake(self) -> None:
        self.inbox.wake()

    def poll_link(self, link: Any, inlet: PushReader) -> bool:
        """For a side whose links the delivery thread can wait on itself (shared memory): attach ``link``, True
        when it does (its messages then go through ``inlet``'s admission); False: the link's own thread must
        hand them to ``inlet``."""
        self._polled_inlet = inlet
        return self.inbox.attach_shm(link)

    # -- negotiation (rospy's connect threads) ----------------------------
    def offered_protocols(self, held: Tuple[str, str] = ("", "")) -> List[List[Any]]:
        """The entries for ``requestTopic`` in the hints' order; ``held``: (protocol, peer) of the link this
        subscription already has to the publisher asked."""
        out: List[List[Any]] = []
        for proto in self.hints.protocols:
            side = self.sides.get(proto)
            if side is not None:
                entry = side.offer(held[1] if held[0] == proto else "")
                if entry is not None:
                    out.append(entry)
            elif proto == TCPROS:
                out.append([TCPROS])
        return out

    def negotiated_sides(self) -> Mapping[str, SubscriptionSide]:
        return self.sides

    def open_first(self, protocol: str) -> bool:
        side = self.sides.get(protocol)
        return side is not None and side.open_first()

    # -- delivery thread ---------------------------------------------------
    def _run(self) -> None:
        next_housekeeping = time.monotonic() + 0.5
        timeout = min(0.5, max(0.005, self.effective.deadline / 4)) if self.deadline.enabled else 0.5
        while not self.closed:
            self.inbox.wait(timeout)
            if self.closed:
                break
            if self.priority != self._thread_priority:
                self._take_priority()
            try:
                self._drain()
                now = time.monotonic()
                if self.writers.holding:
                    self._release_held(now)
                if self.deadline.enabled:
                    self._check_deadline(now)
                if now >= next_housekeeping or self._housekeeping_due:
                    self._housekeeping_due = False
                    next_housekeeping = now + 0.5
                    self._housekeeping(now)
            except Exception:
                if not self.closed:
                    _log.exception("micros_rt: topic %s: delivery error (continuing)", self.topic)

    def _take_priority(self) -> None:
        """On the delivery thread: run at this topic's priority (see core/threadprio.py)."""
        priority = self._thread_priority = self.priority
        if priority is None or not threadprio.enabled():
            return
        nice = threadprio.set_thread_nice(threadprio.nice_for(priority))
        if priority >= TransportPriority.HIGH and not self._high_entered:
            self._high_entered = True
            threadprio.RECEIVE_PRIORITY.enter_high()
        _log.debug("micros_rt: topic %s: delivery thread at priority %s (nice %d)", self.topic, priority.name, nice)

    def _drain(self) -> None:
        """Take what the readers have, deliver it and TCPROS messages, until both are empty."""
        queue, pushed = self.queue, self.pushed
        while not self.closed:
            more = False  # a reader gave a full batch: it may hold more
            for reader in self.readers:
                batch = reader.take(_TAKE_BATCH)
                if batch:
                    more = more or len(batch) >= _TAKE_BATCH
                    self._admit(reader, batch)
            if queue:
                bounded = self.depth is not None
                last_take = time.monotonic() if bounded else 0.0
                while queue:
                    data, info, state = queue.popleft()
                    self._deliver_pulled(data, info, state)
                    if bounded and time.monotonic() - last_take > _RETAKE_SECONDS:
                        break  # take again: the newest queue_size are what ROS delivers
            for link in self.inbox.links:  # shared-memory links the delivery thread waits on itself
                if link.drain(self._deliver_polled, _TAKE_BATCH) >= _TAKE_BATCH:
                    more = True
            for inlet in pushed:
                batch = inlet.take(_TAKE_BATCH)
                if batch:
                    more = more or len(batch) >= _TAKE_BATCH
                    for msg, info in batch:
                        self._deliver_pushed(inlet, msg, info)
            if len(pushed) > 1:
                self._count_pushed_drops()
            if not more and not queue:
                # what arrived meanwhile keeps the reader's condition (or the guard) raised: the next wait
                # returns at once, so no second take just to find a reader empty (1.7 us per message)
                if self._burst_dropped:
                    self._report_burst()
                return

    def _admit(self, reader: ReaderBackend, batch: Any) -> None:
        """Exactly-once and queue_size: each valid sample is queued, held or dropped (and counted)."""
        writers, queue, depth = self.writers, self.queue, self.depth
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
                self._release_held(time.monotonic())  # what it sent before the answer goes first
            if two_readers:
                if info.source_timestamp <= state.last_ts:
                    continue  # the same sample through the other reader
                state.last_ts = info.source_timestamp
            self.received += 1
            queue.append((data, info, state))
            if depth is not None and len(queue) > depth:
                queue.popleft()
                self.dropped_queue_full += 1
                self._burst_dropped += 1

    def _report_burst(self) -> None:
        _log.warning("micros_rt: topic %s: dropped %d messages because callbacks were slower than arrivals "
                     "(queue_size=%s keeps the newest, as ROS does; %d dropped in all). Use a larger queue_size, "
                     "or queue_size=None to lose nothing.", self.topic, self._burst_dropped, self.queue_size,
                     self.dropped_queue_full)
        self._burst_dropped = 0

    def _release_held(self, now: float) -> None:
        for state in self.writers.releasable(now):
            held, state.held = state.held, collections.deque()
            for _t, data, info in held:
                self.received += 1
                self._deliver_pulled(data, info, state)

    def _count_pushed_drops(self) -> None:
        dropped = sum(r.dropped for r in self.pushed)
        if dropped != self._pushed_dropped:
            self._burst_dropped += dropped - self._pushed_dropped
            self._pushed_dropped = dropped

    # -- the one admission path: what the reader did not enforce, whatever the transport -------------
    def _admit_enforced(self, reader: TransportReader, source_ns: int, qos: Optional[Any], *,
                        sent_ns: int = 0) -> bool:
        """Apply source order and the time filter (unless the reader's transport did) and lifespan (Cyclone expires
        samples in its cache, but a sample taken can still wait behind slow callbacks; a writer whose
        QoS is unknown, as over TCPROS, has none); count what is dropped."""
        # first: an out-of-order message must not use up the time filter's window. By the sending time only
        # (``sent_ns``, 0 when the link does not carry one, as TCPROS): a Header stamp is when the data was
        # taken, and publishers of one topic legitimately send data stamped out of order (tf)
        order = self.source_order
        if order.enabled and sent_ns and SOURCE_ORDER not in reader.enforces and not order.admit(sent_ns):
            self.dropped_out_of_order += 1
            return False
        tf = self.time_filter
        if tf.period > 0.0 and TIME_FILTER not in reader.enforces and not tf.admit(time.time()):
            self.dropped_filtered += 1
            return False
        valid = self.lifespan if qos is None else min(self.lifespan, qos.msg_valid_period)
        if source_ns and is_expired(source_ns, time.time_ns(), valid):
            self.dropped_expired += 1
            return False
        return True

    def _deliver_pushed(self, reader: PushReader, msg: Any, info: Any) -> None:
        self.received += 1
        sent_ns = info.source_timestamp
        source_ns = sent_ns or _header_stamp(msg)
        # a link that knows its publisher's QoS (shared memory's, from the answer) has its lifespan and budget
        qos = getattr(info.publication_handle, "qos", None)
        if not self._admit_enforced(reader, source_ns or 0, qos, sent_ns=sent_ns):
            return
        self._deliver(msg, source_ns, qos.latency_budget if qos is not None else 0.0)

    def _deliver_polled(self, msg: Any, source_ns: int, link: Any) -> None:
        inlet = self._polled_inlet
        assert inlet is not None
        self._deliver_pushed(inlet, msg, PushInfo(source_ns, link))

    def _deliver_pulled(self, data: bytes, info: Any, state: WriterState) -> None:
        qos = state.qos
        if not self._admit_enforced(self.readers[0], info.source_timestamp, qos, sent_ns=info.source_timestamp):
            return
        if not state.skew.done:
            self._check_clock_skew(state, time.time_ns() - info.source_timestamp, time.monotonic())
        try:
            msg = self.readers[0].decode(data)
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
            header = {"callerid": (acc.node or acc.conn.endpoint_id) if acc else state.guid, "topic": self.topic,
                      "type": self.data_class._type, "md5sum": self.data_class._md5sum, "transport": "DDS"}
            if acc is not None:
                state.conn_header = header
        msg._connection_header = header
        if state.accepted is not None and state.accepted.latch:
            state.latched = msg
        self._deliver(msg, info.source_timestamp, qos.latency_budget if qos is not None else 0.0)

    def _malformed(self, state: WriterState, exc: Exception) -> None:
        # once per writer in words, then counted: a broken peer must not flood the log
        state.malformed += 1
        self.malformed += 1
        if state.malformed == 1:
            _log.warning("micros_rt: topic %s: dropped a malformed DDS sample from writer %s (%s); is its type "
                         "really %s? Further malformed samples from it are counted, not logged",
                         self.topic, state.guid, str(exc)[:200], self.data_class._type)

    def _deliver(self, msg: Any, source_ts_ns: Optional[int], budget: float) -> None:
        """Hand one message to the callbacks."""
        if source_ts_ns is not None:
            latency = time.time() - source_ts_ns / 1e9
            if self.stats.add(latency, budget):
                _log.debug("micros_rt: topic %s: latency %.3f ms over the publisher's latency_budget %.3f ms "
                           "(%d misses of %d)", self.topic, latency * 1e3, budget * 1e3,
                           self.stats.budget_misses, self.stats.count)
        if self.deadline.enabled:
            silent = self.deadline.delivered(time.monotonic())
            if silent is not None:
                _log.warning("micros_rt: topic %s: data resumed after %.1f s of silence (deadline %g s)",
                             self.topic, silent, self.deadline.deadline)
        self.delivered += 1
        for cb, cb_args in self.callbacks:
            try:
                if cb_args is None:
                    cb(msg)
                else:
                    cb(msg, cb_args)
            except Exception:
                _log.exception("micros_rt: topic %s: callback raised (continuing)", self.topic)

    def _check_clock_skew(self, state: WriterState, age_ns: int, now: float) -> None:
        skew = state.skew.observe(age_ns, now)
        if skew is None:
            return
        acc = state.accepted
        who = acc.pub_uri if acc else state.guid
        node = (state.tag or {}).get("node") or (acc.node if acc else "") or "a non-micros_rt node"
        effects = ("Subscribers ordered by sending timestamp drop its samples in favour of other publishers', "
                   "and msg_valid_period expires them")
        if skew < 0:
            _log.warning("micros_rt: topic %s: the clock of publisher %s (%s, writer %s) runs %.1f s ahead of "
                         "this node's clock (its samples arrive stamped %.1f s in the future). %s; synchronise "
                         "the clocks (NTP/chrony)", self.topic, who, node, state.guid, -skew, -skew, effects)
            return
        # a sample stamped in the past is a clock behind or a sample that waited: a whole window of them
        # (ClockSkewCheck) is more likely the clock, but a node starved of CPU for that long looks the same
        _log.warning("micros_rt: topic %s: every sample of publisher %s (%s, writer %s) in its first %.1f s "
                     "arrived stamped at least %.1f s in the past: its clock runs %.1f s behind this node's "
                     "clock, or its samples waited that long on the way (this node or the network "
                     "overloaded). %s; if the clocks differ, synchronise them (NTP/chrony)", self.topic, who,
                     node, state.guid, state.skew.window, skew, skew, effects)

    def _check_deadline(self, now: float) -> None:
        silent = self.deadline.poll(now)
        if silent is None:
            return
        d = self.deadline.deadline
        if self.deadline.missed_total == 1 or silent < 2 * d:
            _log.warning("micros_rt: topic %s: no message for %.1f s, longer than the deadline of %g s",
                         self.topic, silent, d)
        cb = self.effective.deadline_cb
        if cb is not None:
            try:
                cb(DeadlineMissed(self.topic, d, silent, self.deadline.missed_total))
            except Exception:
                _log.exception("micros_rt: topic %s: deadline_cb raised (continuing)", self.topic)

    def _housekeeping(self, now: float) -> None:
        """Drop links of DDS and shared-memory publishers that vanished (a restart then reconnects) and their
        state."""
        for link in list(self.inbox.links):  # threaded links watch their publisher themselves
            if not link.closed and link.publisher_gone():
                link.notify_gone()
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
                if conn.seen or now - conn.created > 30.0:
                    self.writers.forget_writer(state)
                continue
            if not conn.seen and now - conn.created <= 30.0:
                continue
            if not conn.seen:
                _log.warning("micros_rt: topic %s: publisher %s accepted DDS but its writer was never discovered "
                             "in 30 s; check both nodes' network (ROS_IP, CYCLONEDDS_URI)", self.topic, acc.pub_uri)
            remove_link(self.topic, conn, publisher=False)
            conn.close()
        if self.queue or any(r.pending() for r in self.pushed):
            return  # samples of a gone writer still to deliver: prune next time
        self.writers.prune(matched)

    def replay_latched(self, callback: Callable[..., None], callback_args: Any) -> None:
        """Hand a callback added to this subscription the last message of each connected latching publisher,
        as rospy's ``add_callback`` does (#1852), in the caller's thread as there: DDS writers' from their
        state, TCPROS links' from rospy's connections."""
        msgs = [s.latched for s in self.writers.accepted_states() if s.latched is not None]
        for msg in msgs + patches.latched_messages(self.topic):
            try:
                if callback_args is None:
                    callback(msg)
                else:
                    callback(msg, callback_args)
            except Exception:
                _log.exception("micros_rt: topic %s: callback raised on a latched message (continuing)", self.topic)

    def statistics(self) -> SubscriberStatistics:
        pushed_drops = sum(r.dropped for r in self.pushed)  # dropped before the delivery thread saw them
        return SubscriberStatistics(
            received=self.received + pushed_drops, delivered=self.delivered,
            dropped_queue_full=self.dropped_queue_full + pushed_drops,
            dropped_expired=self.dropped_expired, dropped_filtered=self.dropped_filtered,
            dropped_out_of_order=self.dropped_out_of_order, malformed=self.malformed,
            deadline_missed=self.deadline.missed_total, writers=len(self.writers))

    def close(self) -> None:
        """Unregister from rospy, stop the delivery thread, release readers (the registry calls this once)."""
        if self.closed:
            return
        self.closed = True
        if self.tcpros is not None:
            try:
                self.tcpros.close()
            except Exception as exc:  # rospy at shutdown; the rest is released regardless
                _log.warning("micros_rt: topic %s: rospy could not unregister the subscriber: %s", self.topic, exc)
        feeds, self.feeds = self.feeds, ()
        for feed in feeds:
            feed.close()
        for inlet in self.pushed:
            inlet.close()
        self.inbox.wake()
        if self.thread.is_alive() and threading.current_thread() is not self.thread:
            self.thread.join(timeout=5.0)
        if self._high_entered:
            self._high_entered = False
            threadprio.RECEIVE_PRIORITY.leave_high()
        for state in self.writers.accepted_states():
            if state.accepted is not None:
                state.accepted.conn.close()
        for side in self.sides.values():
            side.close()
        readers, self.readers = self.readers, ()
        for reader in readers:
            reader.close()
        if self.thread.is_alive():
            _log.warning("micros_rt: topic %s: a callback is still running; its wait set is released when it "
                         "returns", self.topic)
        else:
            self.inbox.close()


def _header_stamp(msg: Any) -> Optional[int]:
    if getattr(msg, "_has_header", False):
        st = msg.header.stamp
        ns = int(st.secs) * 1_000_000_000 + int(st.nsecs)
        return ns if ns > 0 else None
    return None


class Subscriber:
    """Returned by :meth:`NodeHandle.subscribe`; rospy's Subscriber API."""

    def __init__(self, sub: _Subscription, registry: EndpointRegistry[_Subscription],
                 callback: Callable[..., None], callback_args: Any) -> None:
        self._sub: Optional[_Subscription] = sub
        self._registry = registry
        self._entry = (callback, callback_args)
        self.resolved_name = sub.topic
        self.name = sub.topic
        self.data_class = sub.data_class
        self.type = sub.data_class._type
        self.md5sum = sub.data_class._md5sum

    def get_num_connections(self) -> int:
        """Publishers connected: what they publish from now on arrives. A DDS publisher counts once this
        subscription's reader has matched its writer (what the writer sent before is not for a volatile reader),
        as a TCPROS one once its connection is up."""
        sub = self._sub
        links = self.connection_transports()
        if sub is not None and sub.tcpros is not None:
            for uri in sub.tcpros.unmatched_dds():
                links.pop(uri, None)
        return len(links)

    def connection_transports(self) -> Dict[str, str]:
        """Publisher URI -> 'DDS' or 'TCPROS' for every current connection (and the MQTT link's URI -> 'MQTT')."""
        sub = self._sub
        links: Dict[str, str] = {}
        if sub is not None:
            for reader in sub.pushed:
                links.update(reader.transports())
        return links

    @property
    def latency(self) -> LatencyStats:
        if self._sub is None:
            raise rospy.ROSException("subscriber is unregistered")
        return self._sub.stats

    def statistics(self) -> SubscriberStatistics:
        """Counters of this topic's subscription (shared by the Subscribers of the topic in this node)."""
        if self._sub is None:
            raise rospy.ROSException("subscriber is unregistered")
        return self._sub.statistics()

    def unregister(self) -> None:
        """Stop receiving; harmless twice."""
        sub, self._sub = self._sub, None
        if sub is None:
            return
        with sub.lock:
            if self._entry in sub.callbacks:
                entries = list(sub.callbacks)
                entries.remove(self._entry)
                sub.callbacks = tuple(entries)
        self._registry.release(sub)

    def __enter__(self) -> "Subscriber":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.unregister()

    close = unregister
