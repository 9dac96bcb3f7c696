"""A micros_rt subscription: per topic and process, the TCPROS reader (rospy's subscriber: master
registration, stock peers), the negotiated transports' sides (shared memory, DDS, a plug-in's:
:mod:`micros_rt.transports.negotiated`), the readers they and the profile's feeds (MQTT) hand messages to, and
the delivery thread that runs the callbacks.

The concerns live apart: waking (the inbox: :mod:`.delivery`, or a transport's wait set), a transport's own
bookkeeping (its side: DDS's exactly-once per writer drains its pulled readers itself), what the subscriber
enforces (the QoS catalogue's admissions, :mod:`micros_rt.qos.enforcement`), counters and latency (:mod:`.stats`).
This module joins them: messages in, callbacks out, every message either delivered or counted in one drop counter.
It names no transport but TCPROS, which every subscription has.
"""

from __future__ import annotations

import functools
import math
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Type

import genpy
import rospy

from ..transports.tcpros import patches
from ..transports.tcpros.reader import TcprosReader
from . import threadprio
from .delivery import EventInbox
from .registry import EndpointRegistry
from .stats import LatencyStats, SubscriberStatistics
from ..transports.base import EndpointSpec, Feed, Inbox, ProfileBackend, PushReader, TransportReader
from ..transports.negotiated import SubscriptionSide
from ..negotiation import TCPROS, TransportHints
from ..qos import (
    UNBOUNDED_QUEUE_DEPTH,
    AdvertiseQoSOptions,
    DeadlineMissed,
    DeadlineMonitor,
    SubscribeQoSOptions,
    TransportPriority,
    is_lossless,
)
from ..qos import options as _catalogue
from ..qos.enforcement import Admission, Lifespan, TimeFilter
from ..log import nonblocking_logger

__all__ = ["Subscriber", "DeadlineMissed", "LatencyStats"]

_log = nonblocking_logger("rosout.micros_rt")
_TAKE_BATCH = 256

#: Seconds between an idle delivery thread's housekeeping wakes: shared-memory links of publishers that died or
#: unregistered are dropped within this (a publisher that unregisters cleanly is dropped at once, by the master's
#: publisherUpdate)
HOUSEKEEPING_PERIOD = 1.0

#: how a node makes one negotiated transport's side of a subscription (the subscription is its host)
SubscriptionSideFactory = Callable[["_Subscription"], SubscriptionSide]


def _admissions(effective: SubscribeQoSOptions, lifespan: float) -> Tuple[Admission, ...]:
    """One check per enforced option of the catalogue that has one, from this subscriber's value of it (its
    options, and its own ``msg_valid_period``), in rank order; each counts in its entry's counter."""
    values: Dict[str, Any] = {"msg_valid_period": lifespan}
    out: List[Admission] = []
    for option in _catalogue.OPTIONS:
        if option.admission is None or option.enforcer is None or option.counter is None:
            continue
        if option.side == "subscribe":
            value = getattr(effective, option.name)
        elif option.name in values:
            value = values[option.name]
        else:
            continue
        check = option.admission(value)
        check.enforcer, check.counter = option.enforcer, option.counter
        out.append(check)
    out.sort(key=lambda a: a.rank)
    return tuple(out)


class _Subscription:
    """Per topic and process: the TCPROS reader, the negotiated sides, the readers they feed and the delivery
    thread."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                 options: Optional[SubscribeQoSOptions], hints: TransportHints, *,
                 tag: Dict[str, str], graph: str, inbox: Optional[Inbox] = None,
                 sides: Mapping[str, SubscriptionSideFactory] = {}, extra: Tuple[ProfileBackend, ...] = (),
                 lifespan: float = math.inf) -> None:
        self.topic = topic
        self.data_class = data_class
        self.queue_size = queue_size
        self.options = options
        self.effective = options or SubscribeQoSOptions(ordered_by_sending_timestamp=False)
        self.hints = hints
        self.tag = tag
        #: the node's graph id (a transport that meets other graphs' writers drops theirs)
        self.graph = graph
        # the newest `depth` are kept, as in ROS; None: nothing dropped (rospy's queue_size=None)
        self.depth: Optional[int] = None if is_lossless(queue_size) else queue_size
        # replaced, never mutated: the delivery thread iterates it without a copy or a lock
        self.callbacks: Tuple[Tuple[Callable[..., None], Any], ...] = ()
        self.lock = threading.Lock()
        self.closed = False
        self.stats = LatencyStats()
        self.received = self.delivered = self.dropped_queue_full = self.malformed = 0
        self.burst_dropped = 0
        #: every enforced option's check (the catalogue's), and the active ones, which every message passes
        self.admissions = _admissions(self.effective, lifespan)
        self._checks: Tuple[Admission, ...] = ()
        self._lifespan: Optional[Lifespan] = next((a for a in self.admissions if isinstance(a, Lifespan)), None)
        self._checks_changed()
        self.deadline = DeadlineMonitor(self.effective.deadline, start=time.monotonic())
        self._deadline_on = self.deadline.enabled
        self._housekeeping_due = False
        # the highest transport priority of the publishers received from; the delivery thread takes it
        # on (core/threadprio.py: its nice value, the interpreter's switch interval for HIGH)
        self.priority: Optional[TransportPriority] = None
        self._thread_priority: Optional[TransportPriority] = None
        self._high_entered = False
        #: what the delivery thread waits on: a transport's wait set the node chose, else an Event
        self.inbox: Inbox = inbox if inbox is not None else EventInbox()
        #: sides with pulled readers, which the delivery thread drains (DDS)
        self.pulled: Tuple[SubscriptionSide, ...] = ()
        #: what a link the delivery thread polls hands each message to (its messages count as ``inlet``'s)
        self._polled_deliver: Callable[[Any, int, Any], None] = lambda msg, source_ns, link: None
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
        self._pushed: Tuple[PushReader, ...] = ()
        self._dropping: Tuple[PushReader, ...] = ()  # pushed readers that drop when full (not TCPROS's)
        self.pushed = (self.tcp_in,) + tuple(r for side in self.sides.values() for r in side.pushed())
        self._pushed_dropped = 0  # drops of non-blocking pushed readers already reported in a burst
        self._extra = extra
        self.feeds: Tuple[Feed, ...] = ()

    # -- what every message passes ---------------------------------------------
    @property
    def lifespan(self) -> float:
        """The subscriber's own msg_valid_period (seconds): a message older than this by its source stamp is
        dropped (``dropped_expired``) whatever its publisher offers; the shorter of the two applies."""
        return math.inf if self._lifespan is None else self._lifespan.valid

    @lifespan.setter
    def lifespan(self, valid: float) -> None:
        if self._lifespan is not None:
            self._lifespan.valid = valid
            self._checks_changed()

    @property
    def time_filter(self) -> TimeFilter:
        """The time filter's check (``time_filter_duration``)."""
        for check in self.admissions:
            if isinstance(check, TimeFilter):
                return check
        raise AttributeError("the QoS catalogue has no time filter")

    def _checks_changed(self) -> None:
        # replaced, never mutated: the delivery thread iterates it without a lock
        self._checks = tuple(a for a in self.admissions if a.active())

    def counters(self) -> Dict[str, int]:
        """The enforced options' counters, by the catalogue's names (the deadline's included)."""
        out: Dict[str, int] = {c: 0 for c in _catalogue.drop_counters()}
        for check in self.admissions:
            out[check.counter] = out.get(check.counter, 0) + check.dropped
        out["deadline_missed"] = self.deadline.missed_total
        return out

    def __getattr__(self, name: str) -> int:
        # an enforced option's counter by its catalogue name (``sub.dropped_filtered``)
        if name.startswith("_") or name in ("admissions", "deadline"):
            raise AttributeError(name)
        counters = self.counters()
        if name in counters:
            return counters[name]
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")

    @property
    def pushed(self) -> Tuple[PushReader, ...]:
        """The readers whose links' threads hand over messages (TCPROS, the feeds', the sides')."""
        return self._pushed

    @pushed.setter
    def pushed(self, readers: Tuple[PushReader, ...]) -> None:
        self._dropping = tuple(r for r in readers if not r.blocking)
        self._pushed = readers

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
    def attach_reader(self, reader: Any) -> None:
        self.inbox.attach(reader)

    def reader_wakes(self) -> bool:
        # a delivery thread whose inbox waits on no reader condition is woken per sample
        return not self.inbox.wakes_on_readers

    def drain_me(self, side: SubscriptionSide) -> None:
        if side not in self.pulled:
            self.pulled = self.pulled + (side,)

    def matches_changed(self) -> None:
        # a transport's thread: a writer matched or went (lease expired, deleted): look at once, not at the
        # next housekeeping round, so a dead publisher leaves the connections within the lease
        self._housekeeping_due = True
        self.inbox.wake()

    def raise_priority(self, qos: Optional[AdvertiseQoSOptions]) -> None:
        """A publisher of ``qos`` connected: its transport priority, and its lifespan's check."""
        if qos is None:
            return
        if self._lifespan is not None and self._lifespan.publisher(qos):
            self._checks_changed()
        if self.priority is None or qos.transport_priority > self.priority:
            # taken on by the delivery thread, at its next wake
            self.priority = TransportPriority(qos.transport_priority)

    def wake(self) -> None:
        self.inbox.wake()

    def poll_link(self, link: Any, inlet: PushReader) -> bool:
        """For a side whose links the delivery thread can wait on itself (shared memory): attach ``link``, True
        when it does (its messages then go through ``inlet``'s admission); False: the link's own thread must
        hand them to ``inlet``."""
        self._polled_deliver = functools.partial(self._deliver_pushed, inlet)
        return self.inbox.attach_link(link)

    def pushed_pending(self) -> bool:
        return any(r.pending() for r in self._pushed)

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
        next_housekeeping = time.monotonic() + HOUSEKEEPING_PERIOD
        deadline_wait = min(0.5, max(0.005, self.effective.deadline / 4)) if self._deadline_on else math.inf
        while not self.closed:
            # idle, the thread wakes for housekeeping only; sooner for a deadline, or while a DDS side holds
            # messages for a negotiation's answer (its ``tick``): each wake of an idle thread costs ~0.1 ms
            self.inbox.wait(min(deadline_wait, 0.5 if self.pulled else HOUSEKEEPING_PERIOD))
            if self.closed:
                break
            if self.priority != self._thread_priority:
                self._take_priority()
            try:
                self._drain()
                now = time.monotonic()
                for side in self.pulled:
                    side.tick(now)
                if self._deadline_on and now >= self.deadline.next_due:
                    self._check_deadline(now)
                if now >= next_housekeeping or self._housekeeping_due:
                    self._housekeeping_due = False
                    next_housekeeping = now + HOUSEKEEPING_PERIOD
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
        """Deliver what the sides' pulled readers, the polled links and the pushed readers have, until all are
        empty."""
        while not self.closed:
            more = False  # a reader gave a full batch: it may hold more
            for side in self.pulled:
                if side.drain(_TAKE_BATCH):
                    more = True
            links = self.inbox.links
            if links:  # links the delivery thread waits on itself (shared memory)
                for link in links:
                    if link.drain(self._polled_deliver, _TAKE_BATCH) >= _TAKE_BATCH:
                        more = True
            for inlet in self._pushed:
                if inlet.queue:
                    batch = inlet.take(_TAKE_BATCH)
                    more = more or len(batch) >= _TAKE_BATCH
                    for msg, info in batch:
                        self._deliver_pushed(inlet, msg, info.source_timestamp, info.publication_handle)
            if self._dropping:
                self._count_pushed_drops()
            if not more:
                # what arrived meanwhile keeps the reader's condition (or the guard) raised: the next wait
                # returns at once, so no second take just to find a reader empty (1.7 us per message)
                if self.burst_dropped:
                    self._report_burst()
                return

    def _report_burst(self) -> None:
        _log.warning("micros_rt: topic %s: dropped %d messages because callbacks were slower than arrivals "
                     "(queue_size=%s keeps the newest, as ROS does; %d dropped in all). Use a larger queue_size, "
                     "or queue_size=None to lose nothing.", self.topic, self.burst_dropped, self.queue_size,
                     self.dropped_queue_full)
        self.burst_dropped = 0

    def _count_pushed_drops(self) -> None:
        dropped = 0
        for reader in self._dropping:
            dropped += reader.dropped
        if dropped != self._pushed_dropped:
            self.burst_dropped += dropped - self._pushed_dropped
            self._pushed_dropped = dropped

    # -- the one admission path: what the reader did not enforce, whatever the transport -------------
    def _admit_enforced(self, reader: TransportReader, source_ns: int, qos: Optional[Any], *,
                        sent_ns: int = 0) -> bool:
        """Every active check of an enforced option the reader's transport did not apply itself, in rank order
        (source order, time filter, lifespan); the first that refuses counts the drop."""
        enforces = reader.enforces
        for check in self._checks:
            if check.enforcer in enforces:
                continue
            if not check.check(sent_ns, source_ns, qos):
                check.dropped += 1
                return False
        return True

    admit = _admit_enforced

    def _deliver_pushed(self, reader: PushReader, msg: Any, sent_ns: int, handle: Any) -> None:
        self.received += 1
        source_ns = sent_ns
        if not sent_ns and getattr(msg, "_has_header", False):  # TCPROS carries no sending time: the Header's
            stamp = msg.header.stamp
            source_ns = max(int(stamp.secs) * 1_000_000_000 + int(stamp.nsecs), 0)
        # a link that knows its publisher's QoS (shared memory's, from the answer) has its lifespan and budget
        qos = getattr(handle, "qos", None)
        if self._checks and not self._admit_enforced(reader, source_ns, qos, sent_ns=sent_ns):
            return
        self.deliver(msg, source_ns or None, qos.latency_budget if qos is not None else 0.0)

    def deliver(self, msg: Any, source_ts_ns: Optional[int], budget: float) -> None:
        """Hand one message to the callbacks."""
        if source_ts_ns is not None:
            latency = time.time() - source_ts_ns / 1e9
            if self.stats.add(latency, budget):
                _log.debug("micros_rt: topic %s: latency %.3f ms over the publisher's latency_budget %.3f ms "
                           "(%d misses of %d)", self.topic, latency * 1e3, budget * 1e3,
                           self.stats.budget_misses, self.stats.count)
        if self._deadline_on:
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
        """Drop links of publishers that vanished (a restart then reconnects) and their state: the polled links'
        and each side's."""
        for link in list(self.inbox.links):  # threaded links watch their publisher themselves
            if not link.closed and link.publisher_gone():
                link.notify_gone()
        for side in self.pulled:
            side.housekeeping(now)

    def replay_latched(self, callback: Callable[..., None], callback_args: Any) -> None:
        """Hand a callback added to this subscription the last message of each connected latching publisher,
        as rospy's ``add_callback`` does (#1852), in the caller's thread as there: the sides' (DDS writers',
        from their state), then TCPROS links' from rospy's connections."""
        msgs = [m for side in self.sides.values() for m in side.latched()]
        for msg in msgs + patches.latched_messages(self.topic):
            try:
                if callback_args is None:
                    callback(msg)
                else:
                    callback(msg, callback_args)
            except Exception:
                _log.exception("micros_rt: topic %s: callback raised on a latched message (continuing)", self.topic)

    def statistics(self) -> SubscriberStatistics:
        pushed_drops = sum(r.dropped for r in self._pushed)  # dropped before the delivery thread saw them
        return SubscriberStatistics.of(
            self.counters(), received=self.received + pushed_drops, delivered=self.delivered,
            dropped_queue_full=self.dropped_queue_full + pushed_drops, malformed=self.malformed,
            writers=sum(side.kept_writers() for side in self.sides.values()))

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
        for inlet in self._pushed:
            inlet.close()
        self.inbox.wake()
        if self.thread.is_alive() and threading.current_thread() is not self.thread:
            self.thread.join(timeout=5.0)
        if self._high_entered:
            self._high_entered = False
            threadprio.RECEIVE_PRIORITY.leave_high()
        for side in self.sides.values():
            side.close()
        if self.thread.is_alive():
            _log.warning("micros_rt: topic %s: a callback is still running; its wait set is released when it "
                         "returns", self.topic)
        else:
            self.inbox.close()


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
