"""A micros_rt subscription: per topic and process, the rospy subscriber, DDS reader(s),
the delivery thread and the QoS the subscriber enforces itself.

Exactly-once: a micros_rt reader hears every micros_rt writer of the topic on
the DDS domain, but delivers only samples of writers whose publisher accepted
DDS in the negotiation with *this* node (graph isolation comes with it: writers
of another ROS graph never negotiate with us). Writers without a micros_rt tag
(ROS 2 nodes) are delivered as they are.

User callbacks run on one delivery thread per subscribed topic, never on a
Cyclone or socket thread.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Deque, Dict, List, Optional, Tuple, Type

import genpy
import rospy

from . import _rospy_compat as compat
from ._runtime import _dds_participant, _depth, _log, _node, announce_to_ros2
from .dds.endpoints import DDSReader, make_user_data
from .dds.participant import DDSParticipant, delete_entity
from .dds.types import DDSType, dds_topic_name, dds_type_for
from .exceptions import MicrosRtError
from .negotiation.hints import DDS, TCPROS, TransportHints
from .qos import (
    AdvertiseQoSOptions,
    SubscribeQoSOptions,
    describe_incompatible_policy,
    plain_reader_qos,
    reader_qos,
)

__all__ = ["Subscriber", "DeadlineMissed", "LatencyStats", "CLOCK_SKEW_WARN_SECONDS"]

_PENDING_SECONDS = 5.0  # how long samples of a not-yet-negotiated writer wait for the answer
#: A writer whose samples arrive stamped further than this from our clock is reported (once).
CLOCK_SKEW_WARN_SECONDS = 1.0
_SKEW_SAMPLES = 10  # samples per writer whose smallest age estimates its clock offset


@dataclass(frozen=True)
class DeadlineMissed:
    """Given to ``deadline_cb``: the topic, the deadline and how long it has been silent."""

    topic: str
    deadline: float
    silent_for: float
    total_count: int


@dataclass
class _Accepted:
    pub_uri: str
    latch: bool
    node: str
    conn: compat.DDSConnection


class _Inbox:
    """What wakes the delivery thread: DDS data, TCPROS messages, connects, close."""

    def __init__(self, participant: Optional[DDSParticipant]) -> None:
        self._event = threading.Event()
        self._guard_up = False
        self.waitset: Any = None
        self.guard: Any = None
        if participant is not None:
            from cyclonedds.core import GuardCondition, WaitSet

            self.waitset = WaitSet(participant.dp)
            self.guard = GuardCondition(participant.dp)
            self.waitset.attach(self.guard)

    def attach(self, condition: Any) -> None:
        self.waitset.attach(condition)

    def wake(self) -> None:
        if self.guard is not None:
            # trigger first, flag second: wait() may then spin once until it sees the flag,
            # but never leaves the guard raised with the flag down (a busy loop)
            self.guard.set(True)
            self._guard_up = True
        else:
            self._event.set()

    def wait(self, timeout: float) -> None:
        if self.waitset is not None:
            self.waitset.wait(int(max(timeout, 0.0) * 1e9))
            if self._guard_up:  # reset only when raised: one C call less per DDS sample
                self._guard_up = False
                self.guard.set(False)
        else:
            self._event.wait(timeout)
            self._event.clear()

    def close(self) -> None:
        """Delete the waitset and guard (after the delivery thread stopped waiting on them)."""
        for entity in (self.waitset, self.guard):
            if entity is not None:
                delete_entity(entity)
        self.waitset = self.guard = None


class _Subscription:
    """Per topic and process: rospy subscriber, DDS reader(s) and the delivery thread."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                 options: Optional[SubscribeQoSOptions], hints: TransportHints) -> None:
        self.topic = topic
        self.data_class = data_class
        self.queue_size = queue_size
        self.options = options
        self.effective = options or SubscribeQoSOptions(ordered_by_sending_timestamp=False)
        self.hints = hints
        self.refcount = 0
        # replaced, never mutated: the delivery thread iterates it without a copy or a lock
        self.callbacks: Tuple[Tuple[Callable[..., None], Any], ...] = ()
        self.malformed: Dict[str, int] = {}  # writer -> malformed samples dropped
        self._conn_headers: Dict[str, Dict[str, str]] = {}
        self.lock = threading.Lock()
        self.closed = False
        self.accepted: Dict[str, _Accepted] = {}
        self.pending: Dict[str, Deque[Tuple[float, bytes, Any, Any]]] = {}
        self.last_ts: Dict[str, int] = {}
        self.header_seq: Dict[str, int] = {}  # per DDS writer: Header.seq is not on the wire
        self.tcp_inbox: Deque[Tuple[Any, float]] = collections.deque(maxlen=_depth(queue_size))
        self.dds_type: Optional[DDSType] = None
        self.reader: Optional[DDSReader] = None
        self.tl_reader: Optional[DDSReader] = None
        self.incompatible_reported: set[int] = set()
        self.participant = _dds_participant() if hints.allows_dds else None
        self.inbox = _Inbox(self.participant)
        self.last_delivery = time.monotonic()
        self.deadline_missed_total = 0
        self.last_filter_pass = -math.inf
        self.stats = LatencyStats()
        # per DDS writer guid: the publisher's QoS from the negotiation answer (budget, lifespan)
        self.writer_qos: Dict[str, AdvertiseQoSOptions] = {}
        self.skew_reported: set[str] = set()
        self.skew_min: Dict[str, Tuple[int, int]] = {}  # writer -> (samples seen, min age ns)
        self.expired_total = 0
        if self.participant is not None:
            try:
                self.dds_type = dds_type_for(data_class)
                self.reader = self._make_reader(transient_local=False)
                self.inbox.attach(self.reader.condition)
            except MicrosRtError as exc:
                _log.warning("micros_rt: topic %s will use TCPROS only: %s", topic, exc)
                self.reader = None
        if hints.protocols == (DDS,) and self.reader is None:
            _log.warning("micros_rt: topic %s: TransportHints allow only DDS, but DDS is unavailable; "
                         "nothing will be received", topic)
        compat.register_subscription(topic, self)
        self.thread = threading.Thread(target=self._run, name=f"micros_rt delivery {topic}", daemon=True)
        self.thread.start()
        # rospy subscriber last: registering triggers the negotiation, which needs the reader.
        self.rospy_sub = rospy.Subscriber(topic, data_class, self._on_tcpros, queue_size=queue_size)

    def _make_reader(self, *, transient_local: bool) -> DDSReader:
        from cyclonedds.core import Listener

        assert self.participant is not None and self.dds_type is not None
        user_data = make_user_data(graph=_node.graph, node=compat.caller_id())
        depth = 1 if transient_local else self.queue_size
        if self.options is None:
            qos = plain_reader_qos(queue_size=depth, transient_local=transient_local, user_data=user_data)
        else:
            qos = reader_qos(self.options, queue_size=depth, transient_local=transient_local,
                             user_data=user_data)
        listener = Listener(  # type: ignore[no-untyped-call]
            on_requested_incompatible_qos=self._incompatible,
            on_subscription_matched=lambda *_: self.inbox.wake())
        reader = DDSReader(self.participant, dds_topic_name(self.topic), self.dds_type, qos, listener)
        announce_to_ros2(add_reader=reader.guid)
        return reader

    def _incompatible(self, _reader: Any, status: Any) -> None:
        # Cyclone thread: only log, never block. A ROS 2 (or foreign) writer whose QoS
        # cannot match ours would otherwise be silence.
        policy = status.last_policy_id
        if policy in self.incompatible_reported:
            return
        self.incompatible_reported.add(policy)
        _log.warning("micros_rt: %s", describe_incompatible_policy(policy, topic=self.topic, side="subscriber"))

    # -- negotiation (rospy's connect threads) ----------------------------
    def protocols(self, topic: str) -> List[List[Any]]:
        out: List[List[Any]] = []
        for proto in self.hints.protocols:
            if proto == DDS and self.reader is not None and self.participant is not None \
                    and self.dds_type is not None:
                out.append([DDS, {
                    "domain": self.participant.domain_id,
                    "topic": dds_topic_name(topic),
                    "type": self.dds_type.type_name,
                    "md5": self.dds_type.md5sum,
                    "qos": self.effective.to_dict(),
                    "reader": self.reader.guid,
                    "participant": self.participant.guid,
                    "graph": _node.graph,
                }])
            elif proto == TCPROS:
                out.append([TCPROS])
        return out

    def connect_dds(self, topic: str, pub_uri: str, params: Any) -> Tuple[int, str, int]:
        if not isinstance(params, dict) or not isinstance(params.get("writer"), str):
            _log.warning("micros_rt: topic %s: publisher %s accepted DDS with malformed parameters %r",
                         topic, pub_uri, params)
            return 0, "malformed DDS answer", 0
        writer = params["writer"]
        latch = bool(params.get("latch", False))
        info = f"DDS connection on topic {dds_topic_name(topic)} from writer {writer}"
        conn = compat.DDSConnection(topic, pub_uri, "i", info, peer_guid=writer,
                                    on_close=self._connection_closed)
        if latch and self.tl_reader is None and self.participant is not None:
            try:
                self.tl_reader = self._make_reader(transient_local=True)
                self.inbox.attach(self.tl_reader.condition)
            except MicrosRtError as exc:
                _log.warning("micros_rt: topic %s: no latched message over DDS: %s", topic, exc)
        try:
            self.writer_qos[writer] = AdvertiseQoSOptions.from_dict(params.get("qos") or {},
                                                                    source=f"publisher {pub_uri}")
        except MicrosRtError as exc:
            _log.warning("micros_rt: topic %s: publisher %s sent unreadable QoS (%s); its latency budget "
                         "and msg_valid_period are not checked", topic, pub_uri, exc)
        with self.lock:
            self.accepted[writer] = _Accepted(pub_uri, latch, str(params.get("node", "")), conn)
            self._conn_headers.pop(writer, None)
        if not compat.add_pseudo_connection(topic, conn, publisher=False):
            with self.lock:
                self.accepted.pop(writer, None)
            return 0, "subscriber closed", 0
        _log.debug("micros_rt: topic %s: receiving from %s over DDS", topic, pub_uri)
        self.inbox.wake()
        return 1, f"Connected topic[{topic}] over DDS", 0

    def _connection_closed(self, conn: compat.DDSConnection) -> None:
        with self.lock:
            acc = self.accepted.get(conn.peer_guid)
            if acc is not None and acc.conn is conn:
                del self.accepted[conn.peer_guid]

    # -- TCPROS (rospy's receive threads): enqueue only ---------------------
    def _on_tcpros(self, msg: Any) -> None:
        self.tcp_inbox.append((msg, time.time()))
        self.inbox.wake()

    # -- delivery thread ---------------------------------------------------
    def _run(self) -> None:
        next_housekeeping = time.monotonic() + 0.5
        while not self.closed:
            self.inbox.wait(self._wait_timeout())
            if self.closed:
                break
            try:
                for reader in (self.reader, self.tl_reader):
                    if reader is not None:
                        self._take(reader)
                while self.tcp_inbox:
                    msg, _t = self.tcp_inbox.popleft()
                    self._deliver(msg, None)
                now = time.monotonic()
                if self.pending:  # connect_dds wakes us: held samples go out right away, in order
                    self._flush_pending(now)
                self._check_deadline(now)
                if now >= next_housekeeping:
                    next_housekeeping = now + 0.5
                    self._housekeeping(now)
            except Exception:
                if not self.closed:
                    _log.exception("micros_rt: topic %s: delivery error (continuing)", self.topic)

    def _wait_timeout(self) -> float:
        timeout = 0.5
        if math.isfinite(self.effective.deadline):
            timeout = min(timeout, max(0.005, self.effective.deadline / 4))
        return timeout

    def _take(self, reader: DDSReader) -> None:
        batch = reader.take_raw(256)
        if not batch:
            return
        two_readers = self.tl_reader is not None
        for data, info in batch:
            if not info.valid_data:
                continue
            wi = reader.writer_info(info.publication_handle)
            if wi is None:
                continue
            if wi.tag is not None:
                acc = self.accepted.get(wi.guid)  # a dict read is atomic; writers hold self.lock
                if acc is None and wi.guid not in self.writer_qos:
                    # not negotiated (yet). A writer negotiated before and now gone (a publisher
                    # that exited) still has the samples it sent us delivered.
                    if wi.tag.get("graph") != _node.graph:
                        continue  # another ROS graph on the same DDS domain
                    q = self.pending.setdefault(wi.guid, collections.deque(maxlen=_depth(self.queue_size)))
                    q.append((time.monotonic(), data, info, reader))
                    continue
                if self.pending and wi.guid in self.pending:
                    self._flush_pending(time.monotonic())  # what it sent before the answer goes first
            if two_readers:
                last = self.last_ts.get(wi.guid, -1)
                if info.source_timestamp <= last:
                    continue  # the same sample through the other reader
                self.last_ts[wi.guid] = info.source_timestamp
            if wi.guid not in self.skew_reported:
                self._check_clock_skew(wi, info.source_timestamp)
            self._deliver_dds_checked(data, info, wi.guid)

    def _deliver_dds_checked(self, data: bytes, info: Any, writer: str) -> None:
        # Lifespan: Cyclone expires samples in its reader cache; a sample taken into our batch
        # can still wait behind slow callbacks, so check its age again right before delivery.
        vp = self._valid_period(writer)
        if math.isfinite(vp) and time.time_ns() - info.source_timestamp > vp * 1e9:
            self.expired_total += 1
            _log.debug("micros_rt: topic %s: dropped a sample of writer %s older than its msg_valid_period "
                       "%.3f s", self.topic, writer, vp)
            return
        self._deliver_dds(data, info, writer)

    def _check_clock_skew(self, wi: Any, source_ts_ns: int) -> None:
        # Same-host or NTP-synced clocks put source stamps within milliseconds of ours. A writer
        # whose stamps are seconds off has a wrong clock: with ordered_by_sending_timestamp its
        # samples lose against every other writer's, and Lifespan expires them on arrival.
        # A sample's age is the clock offset plus its latency, which queueing (a slow callback)
        # only makes longer. So: stamped in the future means a clock ahead at once; a clock
        # behind is the *smallest* age of a writer's first samples (one of them found us idle).
        age = time.time_ns() - source_ts_ns
        n, lowest = self.skew_min.get(wi.guid, (0, age))
        n, lowest = n + 1, min(lowest, age)
        self.skew_min[wi.guid] = (n, lowest)
        if age < -CLOCK_SKEW_WARN_SECONDS * 1e9:
            skew = age / 1e9
        elif n >= _SKEW_SAMPLES and lowest > CLOCK_SKEW_WARN_SECONDS * 1e9:
            skew = lowest / 1e9
        else:
            if n >= _SKEW_SAMPLES:
                self.skew_reported.add(wi.guid)  # judged: in sync, stop checking
            return
        self.skew_reported.add(wi.guid)
        with self.lock:
            acc = self.accepted.get(wi.guid)
        who = acc.pub_uri if acc else wi.guid
        node = (wi.tag or {}).get("node") or (acc.node if acc else "") or "a non-micros_rt node"
        direction = "behind" if skew > 0 else "ahead of"
        _log.warning("micros_rt: topic %s: the clock of publisher %s (%s, writer %s) runs %.1f s %s this "
                     "node's clock (its samples arrive stamped %.1f s %s). Subscribers ordered by sending "
                     "timestamp drop its samples in favour of other publishers', and msg_valid_period expires "
                     "them; synchronise the clocks (NTP/chrony)", self.topic, who, node, wi.guid, abs(skew),
                     direction, abs(skew), "in the past" if skew > 0 else "in the future")

    def _deliver_dds(self, data: bytes, info: Any, writer: str) -> None:
        assert self.dds_type is not None
        try:
            msg = self.dds_type.decode(data)
        except Exception as exc:
            # once per writer in words, then counted: a broken peer must not flood the log
            n = self.malformed.get(writer, 0) + 1
            self.malformed[writer] = n
            if n == 1:
                _log.warning("micros_rt: topic %s: dropped a malformed DDS sample from writer %s (%s); is its "
                             "type really %s? Further malformed samples from it are counted, not logged",
                             self.topic, writer, exc, self.data_class._type)
            else:
                _log.debug("micros_rt: topic %s: malformed sample %d from writer %s", self.topic, n, writer)
            return
        head = msg.header if msg._has_header else msg if msg._type == "std_msgs/Header" else None
        if head is not None:
            # ROS 2 Header has no seq: regenerate it per publisher (DDS writer), 1, 2, ... as rospy counts
            seq = self.header_seq.get(writer, 0) + 1
            self.header_seq[writer] = seq
            head.seq = seq
        header = self._conn_headers.get(writer)
        if header is None:
            # one dict per writer, shared by its messages as rospy shares one per connection
            acc = self.accepted.get(writer)
            header = {
                "callerid": acc.conn.endpoint_id if acc else writer,
                "topic": self.topic, "type": self.data_class._type, "md5sum": self.data_class._md5sum,
                "transport": "DDS",
            }
            if acc is not None:
                self._conn_headers[writer] = header
        msg._connection_header = header
        self._deliver(msg, info.source_timestamp, writer)

    def _deliver(self, msg: Any, source_ts_ns: Optional[int], writer: Optional[str] = None) -> None:
        """Hand one message to the callbacks; ``writer`` is the DDS writer (None on TCPROS)."""
        now_wall = time.time()
        if source_ts_ns is None:
            stamp = _header_stamp(msg)
            if stamp is not None:
                source_ts_ns = stamp
            # TCPROS link: the subscriber enforces what DDS would
            f = self.effective.time_filter_duration
            if f > 0:
                if now_wall - self.last_filter_pass < f:
                    return
                self.last_filter_pass = now_wall
        if source_ts_ns is not None:
            latency = now_wall - source_ts_ns / 1e9
            budget = self._latency_budget(writer)
            if self.stats.add(latency, budget):
                _log.debug("micros_rt: topic %s: latency %.3f ms over the publisher's latency_budget %.3f ms "
                           "(%d misses of %d)", self.topic, latency * 1e3, budget * 1e3,
                           self.stats.budget_misses, self.stats.count)
        self.last_delivery = time.monotonic()
        for cb, cb_args in self.callbacks:
            try:
                if cb_args is None:
                    cb(msg)
                else:
                    cb(msg, cb_args)
            except Exception:
                _log.exception("micros_rt: topic %s: callback raised (continuing)", self.topic)

    def _valid_period(self, writer: str) -> float:
        """The publisher's msg_valid_period (seconds), known for micros_rt publishers on DDS links.

        A TCPROS link carries no QoS (stock publishers have none, and the TCPROS handshake has no
        field for it), so there it is unknown and nothing expires.
        """
        q = self.writer_qos.get(writer)
        return q.msg_valid_period if q is not None else math.inf

    def _latency_budget(self, writer: Optional[str]) -> float:
        q = self.writer_qos.get(writer) if writer is not None else None
        return q.latency_budget if q is not None else 0.0

    def _check_deadline(self, now: float) -> None:
        d = self.effective.deadline
        if not math.isfinite(d) or self.effective.deadline_cb is None:
            return
        silent = now - self.last_delivery
        if silent >= d:
            self.deadline_missed_total += 1
            self.last_delivery = now  # once per period of silence
            try:
                self.effective.deadline_cb(DeadlineMissed(self.topic, d, silent, self.deadline_missed_total))
            except Exception:
                _log.exception("micros_rt: topic %s: deadline_cb raised (continuing)", self.topic)

    def _flush_pending(self, now: float) -> None:
        """Deliver held samples of writers whose negotiation finished; expire the others."""
        for guid in list(self.pending):
            q = self.pending[guid]
            if guid in self.accepted:
                del self.pending[guid]
                for _t, data, info, _r in q:
                    self._deliver_dds_checked(data, info, guid)
            else:
                while q and now - q[0][0] > _PENDING_SECONDS:
                    q.popleft()
                if not q:
                    del self.pending[guid]

    def _housekeeping(self, now: float) -> None:
        # a DDS publisher that vanished: drop its pseudo-connection so a restart reconnects
        if self.reader is None:
            return
        matched = set(self.reader.matched_writer_guids())
        if self.tl_reader is not None:
            matched |= set(self.tl_reader.matched_writer_guids())
        for guid, acc in list(self.accepted.items()):
            conn = acc.conn
            if guid in matched:
                conn.seen = True
            elif conn.seen or now - conn.created > 30.0:
                if not conn.seen:
                    _log.warning("micros_rt: topic %s: publisher %s accepted DDS but its writer was never "
                                 "discovered in 30 s; check both nodes' network (ROS_IP, CYCLONEDDS_URI)",
                                 self.topic, acc.pub_uri)
                else:
                    _log.debug("micros_rt: topic %s: DDS publisher %s is gone", self.topic, acc.pub_uri)
                compat.remove_pseudo_connection(self.topic, conn, publisher=False)
                conn.close()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        compat.register_subscription(self.topic, None)
        with _node.lock:
            if _node.subscriptions.get(self.topic) is self:
                del _node.subscriptions[self.topic]
        try:
            self.rospy_sub.unregister()
        except Exception:
            pass
        self.inbox.wake()
        if threading.current_thread() is not self.thread:
            self.thread.join(timeout=2.0)
        for r in (self.reader, self.tl_reader):
            if r is not None:
                if not rospy.is_shutdown():
                    announce_to_ros2(remove=r.guid)
                r.close()
        self.reader = self.tl_reader = None
        if not self.thread.is_alive():
            self.inbox.close()


class LatencyStats:
    """Source stamp to callback latency of one subscription (seconds).

    The latency is measured from the publisher's source timestamp (DDS) or Header stamp (TCPROS,
    stamped messages only) to the moment the callback is called, so it includes time spent waiting
    behind earlier callbacks. ``count``, ``mean`` and ``max`` cover every message; ``p50``/``p99``
    the last ``keep`` ones. ``budget_misses`` counts messages later than their publisher's
    ``latency_budget`` (only publishers that declare a budget > 0, i.e. micros_rt publishers on DDS).
    """

    def __init__(self, keep: int = 4096) -> None:
        self.samples: Deque[float] = collections.deque(maxlen=keep)
        self.count = 0
        self.total = 0.0
        self.max = 0.0
        self.budget_checked = 0
        self.budget_misses = 0

    def add(self, latency: float, budget: float = 0.0) -> bool:
        """Record one latency; True when it missed ``budget`` (> 0)."""
        self.samples.append(latency)
        self.count += 1
        self.total += latency
        if latency > self.max:
            self.max = latency
        if budget > 0.0:
            self.budget_checked += 1
            if latency > budget:
                self.budget_misses += 1
                return True
        return False

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100, nearest rank) of the recent latencies; NaN when empty."""
        data = sorted(self.samples)
        if not data:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * len(data)))
        return data[min(rank, len(data)) - 1]

    @property
    def p50(self) -> float:
        return self.percentile(50)

    @property
    def p99(self) -> float:
        return self.percentile(99)

    def summary(self) -> Dict[str, float]:
        """count, mean, p50, p99, max (seconds), budget_checked and budget_misses, as a dict."""
        data = sorted(self.samples)

        def pct(q: float) -> float:
            if not data:
                return math.nan
            return data[min(max(1, math.ceil(q / 100.0 * len(data))), len(data)) - 1]

        return {"count": self.count, "mean": self.mean, "p50": pct(50), "p99": pct(99),
                "max": self.max if self.count else math.nan,
                "budget_checked": self.budget_checked, "budget_misses": self.budget_misses}


def _header_stamp(msg: Any) -> Optional[int]:
    if getattr(msg, "_has_header", False):
        st = msg.header.stamp
        ns = st.secs * 1_000_000_000 + st.nsecs
        return ns if ns > 0 else None
    return None


class Subscriber:
    """Returned by :meth:`NodeHandle.subscribe`; rospy's Subscriber API."""

    def __init__(self, sub: _Subscription, callback: Callable[..., None], callback_args: Any) -> None:
        self._sub: Optional[_Subscription] = sub
        self._entry = (callback, callback_args)
        self.resolved_name = sub.topic
        self.name = sub.topic
        self.data_class = sub.data_class
        self.type = sub.data_class._type
        self.md5sum = sub.data_class._md5sum

    def get_num_connections(self) -> int:
        """Publishers connected, over DDS and TCPROS."""
        sub = self._sub
        if sub is None:
            return 0
        impl = sub.rospy_sub.impl
        return 0 if impl is None else len(impl.connections)

    def connection_transports(self) -> Dict[str, str]:
        """Publisher URI -> 'DDS' or 'TCPROS' for every current connection."""
        sub = self._sub
        if sub is None or sub.rospy_sub.impl is None:
            return {}
        return {c.endpoint_id: getattr(c, "transport_type", "TCPROS") for c in sub.rospy_sub.impl.connections}

    @property
    def latency(self) -> LatencyStats:
        if self._sub is None:
            raise rospy.ROSException("subscriber is unregistered")
        return self._sub.stats

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
        with _node.lock:
            sub.refcount -= 1
            last = sub.refcount <= 0
        if last:
            sub.close()

    def __enter__(self) -> "Subscriber":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.unregister()

    close = unregister
