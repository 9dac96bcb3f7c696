"""The transport interface: what a publication and a subscription ask of every data plane.

Every transport (TCPROS, DDS, MQTT, the microcontroller link) opens one writer per publication and one
reader per subscription, and the per-topic endpoints (:mod:`micros_rt.core.publication`,
:mod:`micros_rt.core.subscription`) talk to these few methods only, as rospy's ``ProtocolHandler`` and
httpx's transport interface keep their callers free of per-transport ``if`` chains.

Writers are two-phase so that a bad message is refused before anything is sent on any transport:
every writer :meth:`~TransportWriter.prepare`\\s (serializes, raising ``genpy.SerializationError``), then
every writer :meth:`~TransportWriter.send`\\s what it prepared. ``prepare`` returns None when nobody is
there to receive (the message is then not encoded for that transport at all).

Readers come in two kinds, behind one :class:`TransportReader` shape (``take``/``decode``/``close``):

- *polled* readers (DDS) keep received samples in the transport (Cyclone's reader cache) until the
  subscription's delivery thread takes them; their ``condition`` wakes that thread's wait set;
- *pushed* readers (TCPROS, MQTT, microcontroller UDP) get messages on the transport's own I/O threads;
  :class:`PushReader` queues them per reader so that a slow subscription never blocks a network
  thread that other topics share (paho's, a UDP receive thread). Only a thread of the link's own
  (one rospy receive thread per TCPROS connection) waits for room, as rospy's does.

Each reader declares in :attr:`TransportReader.enforces` which subscriber QoS the transport applies
itself (Cyclone: the time-based filter); the subscription's one admission path applies the rest.
"""

from __future__ import annotations

import collections
import queue
import importlib
import threading
import time
from dataclasses import dataclass
from typing import (Any, Callable, Deque, Dict, FrozenSet, List, Optional, Protocol, Sequence, Set, Tuple, Type,
                    runtime_checkable)

import genpy

from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = ["BACKOFF_FIRST", "BACKOFF_MAX", "BackPressuredWriter", "send_with_backoff", "Backend", "EndpointSpec", "Feed", "MirrorWriter", "PROFILE_BACKENDS", "Inbox", "ProfileBackend", "PushInfo",
           "PushReader", "ReaderBackend", "Wakeup", "RemoteWriter", "Sample", "TIME_FILTER", "LIFESPAN", "SOURCE_ORDER", "TransportReader",
           "TransportWriter", "WriterBackend", "close_profile_backends", "profile_backends"]

# Names of the subscriber QoS a reader can enforce natively (:attr:`TransportReader.enforces`): the catalogue's
# enforcers (micros_rt.qos.options.OPTIONS)
from ..qos.options import LIFESPAN, SOURCE_ORDER, TIME_FILTER  # noqa: E402


@dataclass(frozen=True)
class EndpointSpec:
    """One topic endpoint as the transport needs to know it."""

    topic: str                         # resolved ROS name
    data_class: Type[genpy.Message]
    queue_size: Optional[int]          # None/0: lossless (reliable, keep all, back-pressure)
    latch: bool                        # writer: keep the last message for late joiners; reader: want it
    tag: Dict[str, str]                # micros_rt identity (graph, node), visible to peers


@dataclass(frozen=True)
class RemoteWriter:
    """A peer writer a reader heard: its id and its micros_rt tag (None for foreign, e.g. ROS 2)."""

    guid: str
    tag: Optional[Dict[str, str]]


#: One received sample: (payload, info) where ``info`` has ``valid_data`` (bool), ``source_timestamp``
#: (ns, 0 when unknown) and ``publication_handle`` (the writer, for :meth:`ReaderBackend.writer`).
#: Cyclone's own SampleInfo has exactly these, so the DDS path builds no object of its own per sample (but
#: for large samples taken with the GIL released: a small ``TakenInfo`` each, see transports/dds/endpoints.py).
Sample = Tuple[Any, Any]


@runtime_checkable
class TransportWriter(Protocol):
    """A publication's writer on one transport."""

    protocol: str

    def prepare(self, msg: Any) -> Any:
        """Serialize ``msg`` for this transport (None: nobody to send to); raise
        ``genpy.SerializationError`` on a bad value, before anything is sent anywhere."""

    def send(self, prepared: Any) -> None:
        """Send what :meth:`prepare` returned; may block on back-pressure (bounded, then raises)."""

    def close(self) -> None: ...


@runtime_checkable
class BackPressuredWriter(TransportWriter, Protocol):
    """A writer that can say "not now" instead of blocking: the publication puts a send queue in front of
    it (:mod:`micros_rt.core.send_queue`), so one topic's back-pressure never holds another topic's ``publish()``."""

    def try_send(self, prepared: Any) -> bool:
        """Send at once and return True, or return False (nothing sent) when the transport has no room
        now (a reliable DDS writer with too much unacknowledged data). Waits at most for the network
        to take the bytes (a socket buffer behind a slow link), and then without holding the GIL."""

    def may_wait(self, prepared: Any) -> bool:
        """True when sending this sample can wait on the network (a large sample, many datagrams): a
        KEEP_LAST send queue then sends it from its own thread, so ``publish()`` does not wait."""


#: The waits between tries of a writer with no room: from BACKOFF_FIRST, doubling, at most BACKOFF_MAX
#: seconds (an acknowledgement on loopback takes ~0.1 ms; on a radio link many ms).
BACKOFF_FIRST = 50e-6
BACKOFF_MAX = 0.002


def send_with_backoff(try_send: Callable[[Any], bool], prepared: Any, timeout: float,
                      closed: Callable[[], bool] = lambda: False,
                      wait: Optional[Callable[[float], None]] = None, *,
                      first: float = BACKOFF_FIRST, most: float = BACKOFF_MAX,
                      clock: Callable[[], float] = time.monotonic) -> bool:
    """Try ``try_send(prepared)`` until it succeeds (True), ``timeout`` seconds of ``clock`` passed since the
    first try (``math.inf``: never) or ``closed()`` is true before a pause (False then), waiting between tries
    with ``wait(seconds)`` (the transport's own wait for room, which returns as soon as there is some; a sleep
    when it has none), ``first`` seconds, doubling, at most ``most``. The waiting never holds the GIL:
    Cyclone's own blocking write does, and stalls the whole process (measured: a thread counting got 0.3 % of
    its rate while a write waited 1.5 s for a stopped reader's acknowledgements). The one retry loop: anything
    retried with backoff (a send queue's samples, a peer's XML-RPC call) goes through it.

    >>> now = [0.0]
    >>> def pause(seconds: float) -> None: now[0] += seconds
    >>> send_with_backoff(lambda _: False, None, 0.01, wait=pause, first=0.001, most=0.004, clock=lambda: now[0])
    False
    >>> round(now[0], 3)  # 1 + 2 + 4 + 4 ms: the first try after the timeout gives up
    0.011
    """
    if try_send(prepared):
        return True
    deadline = clock() + timeout
    pause = first
    pausing = time.sleep if wait is None else wait
    while not closed():
        pausing(pause)
        if try_send(prepared):
            return True
        if clock() >= deadline:
            return False
        pause = min(pause * 2, most)
    return False


@runtime_checkable
class TransportReader(Protocol):
    """A subscription's reader on one transport."""

    protocol: str
    #: subscriber QoS the transport applies itself (:data:`TIME_FILTER`, :data:`LIFESPAN`, :data:`SOURCE_ORDER`)
    enforces: FrozenSet[str]

    def take(self, n: int) -> Sequence[Sample]:
        """Up to ``n`` received samples, oldest first, without blocking."""

    def decode(self, payload: Any) -> Any:
        """A genpy message from a payload; raise ``ValueError`` on a malformed one."""

    def close(self) -> None: ...


class WriterBackend(TransportWriter, Protocol):
    """A negotiated transport's writer (DDS): it also says which readers it reaches."""

    guid: str

    def matched_peers(self) -> Set[str]:
        """Ids of the readers this writer reaches now."""


class ReaderBackend(TransportReader, Protocol):
    """A negotiated transport's reader (DDS): samples carry the writer they came from, and the
    subscription delivers only those of writers whose publisher accepted this transport."""

    guid: str

    def writer(self, handle: Any) -> Optional[RemoteWriter]:
        """The writer behind a sample's handle (None when it is already gone)."""

    def matched_writers(self) -> Set[str]:
        """Ids of the writers this reader hears now."""


class Backend(Protocol):
    """A negotiated data plane: opens writers and readers. ``wake`` is called (from any thread) when data
    or a match arrives; a back end may instead expose a native wait condition the inbox attaches to."""

    protocol: str

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> WriterBackend: ...

    def open_reader(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                    wake: Callable[[], None], on_incompatible: Callable[[int], None]) -> ReaderBackend: ...

    def describe(self) -> List[str]:
        """Words for ``rosnode info`` and logs (domain, interface)."""


class Inbox(Protocol):
    """What a subscription's delivery thread waits on: an Event (:class:`micros_rt.core.delivery.EventInbox`), or
    a transport's native wait set, which its readers' conditions (DDS) or its links' listeners (shared memory)
    wake. The node picks one per subscription (:func:`micros_rt.transports.builtin.inbox_for`)."""

    #: links the delivery thread waits on and drains itself (``drain(deliver, n)``, ``closed``,
    #: ``publisher_gone()``, ``notify_gone()``), by link
    links: Dict[Any, Any]
    #: True when a pulled reader's native condition wakes the thread (no wake per sample needed)
    wakes_on_readers: bool

    def attach(self, reader: Any) -> None:
        """Wake on ``reader``'s native condition when this wait set can."""

    def detach(self, reader: Any) -> None: ...

    def attach_link(self, link: Any) -> bool:
        """Let the delivery thread wait on ``link`` and drain it itself (True); False: the link's own thread must
        hand its messages over."""

    def wake(self) -> None: ...

    def wait(self, timeout: float) -> None: ...

    def close(self) -> None:
        """Release the wait set (after the delivery thread stopped waiting on it) and the links it holds."""


class Wakeup:
    """A wake-up flag between threads, cheaper than ``threading.Event`` (whose set and wait are a dozen Python
    calls on a Condition, per message when messages come one at a time): a C queue holding at most one token.

    :meth:`set` after new data; :meth:`wait` returns at once when a set came since the last wait, else at the first
    set or after ``timeout``. A set that comes while the waiter is draining is never lost: the flag is cleared
    before the waiter looks at the data, so a set after that puts a token again."""

    __slots__ = ("_tokens", "_raised")

    def __init__(self) -> None:
        self._tokens: "queue.SimpleQueue[None]" = queue.SimpleQueue()
        self._raised = False

    def set(self) -> None:
        if not self._raised:
            self._raised = True
            self._tokens.put(None)

    def is_set(self) -> bool:
        return self._raised

    def wait(self, timeout: Optional[float]) -> None:
        try:
            self._tokens.get(timeout=timeout)
        except queue.Empty:
            return
        self._raised = False


class PushInfo:
    """The ``info`` of a pushed sample (the shape of Cyclone's SampleInfo that the core reads)."""

    __slots__ = ("source_timestamp", "publication_handle")
    valid_data = True

    def __init__(self, source_timestamp: int, publication_handle: Any) -> None:
        self.source_timestamp = source_timestamp
        self.publication_handle = publication_handle


class PushReader:
    """The reader of a transport whose I/O threads hand over decoded messages (TCPROS, MQTT, UDP).

    Each reader has its own queue of ``depth`` messages (None: unbounded, for lossless subscriptions).
    :meth:`put` from a thread of the link's own (``blocking=True``: one rospy receive thread per TCPROS
    connection) waits for room, which slows that link only, as rospy's back-pressure does. :meth:`put`
    from a thread other topics share (``blocking=False``: paho's network thread, a UDP receive thread)
    never waits: a full queue drops its oldest message and counts it in :attr:`dropped`, as ROS keeps the
    newest ``queue_size``.
    """

    enforces: FrozenSet[str] = frozenset()

    def __init__(self, protocol: str, depth: Optional[int], wake: Callable[[], None], *, blocking: bool,
                 links: Optional[Callable[[], Dict[str, str]]] = None) -> None:
        self.protocol = protocol
        self.depth = depth
        self.blocking = blocking
        self.dropped = 0
        self.closed = False
        self._wake = wake
        self._queue: Deque[Sample] = collections.deque()
        #: the queue itself, for a cheap "anything there?" (the delivery thread takes only from a reader that has)
        self.queue = self._queue
        self._space = threading.Condition()
        self._waiting = 0  # put()s waiting for room (take() wakes them only then)
        #: link id -> protocol name of the links feeding this reader (for ``connection_transports()``)
        self.links = links

    def put(self, msg: Any, source_ns: int = 0, link: Any = None) -> None:
        """Queue one message (any thread). ``source_ns``: its sending time when known (a Header stamp)."""
        sample = (msg, PushInfo(source_ns, link))
        depth, q = self.depth, self._queue
        if depth is None:
            q.append(sample)
        elif self.blocking:
            if len(q) >= depth:
                with self._space:
                    self._waiting += 1  # before the check: a take() meanwhile then notifies
                    try:
                        while len(q) >= depth and not self.closed:
                            self._space.wait(0.5)  # back-pressure to this link only
                    finally:
                        self._waiting -= 1
            q.append(sample)
        else:
            q.append(sample)
            while len(q) > depth:
                try:
                    q.popleft()
                except IndexError:  # the delivery thread took it meanwhile
                    break
                self.dropped += 1
        self._wake()

    def take(self, n: int) -> Sequence[Sample]:
        q = self._queue
        out: List[Sample] = []
        while q and len(out) < n:
            try:
                out.append(q.popleft())
            except IndexError:
                break
        if out and self._waiting:
            with self._space:
                self._space.notify_all()
        return out

    def pending(self) -> int:
        return len(self._queue)

    @staticmethod
    def decode(payload: Any) -> Any:
        return payload  # the transport decoded it on its own thread

    def transports(self) -> Dict[str, str]:
        """Link id -> protocol name, for ``Subscriber.connection_transports()``."""
        return {} if self.links is None else self.links()

    def close(self) -> None:
        """Stop accepting and release a thread waiting for room (harmless twice)."""
        if self.closed:
            return
        self.closed = True
        with self._space:
            self._space.notify_all()


# ---------------------------------------------------------------------------------------------------
# Transports a YAML profile attaches to topics beside the negotiated DDS/TCPROS link (MQTT today).
# A publication mirrors its messages to each writer they open; a subscription is fed through a
# PushReader of its own per feed, into the same admission path as every other reader.


class MirrorWriter(TransportWriter, Protocol):
    """A profile transport's writer: two-phase like every :class:`TransportWriter` (prepare raises on a
    bad value before anything is sent anywhere; send does not raise for a peer or broker that is away)."""


class Feed(Protocol):
    """Messages from a profile transport into a subscription (``deliver(msg)`` per message, from the
    transport's I/O thread; it never blocks)."""

    protocol: str

    def transports(self) -> Dict[str, str]:
        """Link id -> protocol name, for ``Subscriber.connection_transports()``."""

    def close(self) -> None: ...


class ProfileBackend(Protocol):
    """A transport chosen per topic by the YAML profile: opens a writer or a feed when one of its rules
    names the topic, else returns None."""

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> Optional[MirrorWriter]: ...

    def open_feed(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                  deliver: Callable[[Any], None]) -> Optional[Feed]: ...


#: profile section -> module whose ``profile_backend(profile, graph=..., node=...)`` returns the
#: :class:`ProfileBackend` for it. Imported only when a node's profile has that section.
PROFILE_BACKENDS: Dict[str, str] = {"mqtt": "micros_rt.transports.mqtt"}


def close_profile_backends() -> None:
    """Close the profile transports this process opened (at node shutdown): each section's module that
    was imported closes its own (``close_profile_backend()``)."""
    import sys

    for module in PROFILE_BACKENDS.values():
        loaded = sys.modules.get(module)
        close = getattr(loaded, "close_profile_backend", None)
        if close is not None:
            close()


def profile_backends(profile: Any, *, graph: str, node: str) -> Tuple[ProfileBackend, ...]:
    """The profile transports ``profile`` (a :class:`micros_rt.QoSProfile` or None) asks for."""
    if profile is None:
        return ()
    found: List[ProfileBackend] = []
    for section, module in PROFILE_BACKENDS.items():
        if getattr(profile, section, None):
            found.append(importlib.import_module(module).profile_backend(profile, graph=graph, node=node))
    return tuple(found)
