"""rospy's patches: the one module that changes rospy's private ``rospy.impl`` layer (the TCPROS transport's
writer and reader, :mod:`.writer` and :mod:`.reader`, use what it keeps: rospy's own endpoint classes).

micros_rt plugs into ROS 1's protocol negotiation (``requestTopic``) on both
sides:

* publisher side: ``ROSHandler.requestTopic`` is wrapped; for a micros_rt
  publication the entries of negotiated transports ('SHM', 'DDS') a subscriber
  offers are judged by the publication's sides (accepted, or declined with a
  logged reason so the next protocol, TCPROS, is tried); for everything else
  they are removed and rospy decides as usual.
* subscriber side: ``ROSHandler._connect_topic`` is wrapped; for a micros_rt
  subscription the protocol list follows the subscription's TransportHints and
  a negotiated transport's answer creates a pseudo-connection instead of a
  socket (its side reads the answer and connects); and
  ``RegManager.publisher_update`` no longer lets a stale publisher list erase a
  newer one (:func:`_merging_publisher_update`).

Pseudo-connections live in rospy's own connection lists, so ``getBusInfo``
(``rosnode info``), ``get_num_connections`` and ``has_connection`` stay true.
"""

from __future__ import annotations

import contextlib
import errno
import select
import socket
import urllib.parse
import logging
import threading
import time
import xmlrpc.client
from typing import TYPE_CHECKING, Any, Callable, Dict, Iterator, List, Mapping, Optional, Protocol, Tuple

import genpy
import rospy
import rospy.core
import rospy.impl.init
import rospy.impl.masterslave as masterslave
import rospy.impl.registration
import rospy.names
import rospy.topics
import rosgraph
from ...negotiation import TCPROS, MalformedNegotiationError, RateLimitedLog
from ...negotiation import OfferJudge, choose_protocol
from rospy.impl.tcpros_pubsub import QueuedConnection
from rospy.impl.registration import (
    RegManager,
    Registration,
    get_registration_listeners,
    get_service_manager,
    get_topic_manager,
)
from ...log import nonblocking_logger
from ..base import send_with_backoff
from .xmlrpc import TimeoutTransport

if TYPE_CHECKING:
    from ..negotiated import SubscriptionSide

__all__ = [
    "MasterWatch",
    "PublicationHook",
    "SubscriptionHook",
    "install",
    "caller_id",
    "add_pseudo_connection",
    "add_node_api_method",
    "prompt_registration_poll",
    "bus_info",
    "remove_pseudo_connection",
    "short",
    "transport_socket",
    "ROSPY_PUBLISHER",
    "ROSPY_SUBSCRIBER",
    "ROSPY_SERVICE",
    "ROSPY_SERVICE_PROXY",
    "topic_connections",
    "latched_messages",
    "set_publisher_tcp_nodelay",
    "topic_impl",
]

_log = nonblocking_logger("rosout.micros_rt.negotiation")



def _is_pseudo(conn: Any) -> bool:
    """A negotiated transport's link (:class:`micros_rt.transports.links.PseudoLink`): no socket, writes nothing."""
    return bool(getattr(conn, "pseudo_link", False))


class PublicationHook(Protocol):
    """What the publisher side of the negotiation asks a micros_rt publication."""

    def negotiated_transports(self, subscriber: str) -> Dict[str, OfferJudge]:
        """The transports this publication negotiates with ``subscriber``, by protocol name (DDS)."""

    def on_tcpros_connection(self, conn: Any, sock: Any) -> None:
        """A TCPROS subscriber connected (mark its socket)."""


class SubscriptionHook(Protocol):
    """What the subscriber side of the negotiation asks a micros_rt subscription."""

    def offered_protocols(self, held: Tuple[str, str] = ("", "")) -> List[List[Any]]:
        """Protocol entries to offer, in preference order, e.g. [['SHM', {...}], ['DDS', {...}], ['TCPROS']];
        ``held``: (protocol, peer) of the link already made to this publisher (an SHM channel, a DDS writer)."""

    def negotiated_sides(self) -> "Mapping[str, SubscriptionSide]":
        """The negotiated transports' sides, by protocol name: how to read an answer and connect."""

    def open_first(self, protocol: str) -> bool:
        """Open what a lazy offer of ``protocol`` left out (a publisher answered "open first": DDS's reader);
        True when it is there now."""


_find_publication: Callable[[str], Optional[PublicationHook]] = lambda topic: None
_find_subscription: Callable[[str], Optional[SubscriptionHook]] = lambda topic: None
_install_lock = threading.Lock()
_installed = False
_declines = RateLimitedLog(_log)


def short(text: str, limit: int = 80) -> str:
    """A remote-supplied string cut for a log line (a caller id can be a megabyte long)."""
    return text if len(text) <= limit else text[:limit - 3] + "..."


def caller_id() -> str:
    return str(rospy.names.get_caller_id())


def _publisher_has_connection(self: Any, endpoint_id: str) -> bool:
    """rospy's ``_TopicImpl.has_connection`` for publishers: a subscriber's link counts once a message published
    now reaches it. A TCPROS link enters rospy's list after its handshake, when the subscriber reads; a shared-memory
    or DDS link enters it when the publisher answers ``requestTopic``, before the subscriber has attached or
    matched (:attr:`micros_rt.transports.links.PseudoLink.ready`). actionlib's ``wait_for_server`` asks this of the goal publisher: on a
    loaded host its first goal went out before the server's subscriber attached, was lost, and the goal stayed
    PENDING (3 of 10 runs of an actionlib client and server under ``micros-rt run``; 0 of 10 with this)."""
    for c in self.connections:  # rospy replaces the list, never mutates it: no lock needed (as rospy's own)
        if c.endpoint_id == endpoint_id:
            ready = getattr(c, "ready", None)
            return True if ready is None else bool(ready())
    return False


def add_pseudo_connection(topic: str, conn: Any, *, publisher: bool) -> bool:
    """Put ``conn`` into rospy's connection list of ``topic``.

    On the publisher side the base ``_TopicImpl.add_connection`` is used on purpose:
    ``_PublisherImpl.add_connection`` would wrap it in a queue thread and re-send the
    latched message through rospy, while DDS durability already does that.
    """
    tm = get_topic_manager()
    impl = tm.get_publisher_impl(topic) if publisher else tm.get_subscriber_impl(topic)
    if impl is None:
        return False
    return bool(rospy.topics._TopicImpl.add_connection(impl, conn))


def remove_pseudo_connection(topic: str, conn: Any, *, publisher: bool) -> None:
    tm = get_topic_manager()
    impl = tm.get_publisher_impl(topic) if publisher else tm.get_subscriber_impl(topic)
    if impl is not None and conn in impl.connections:
        impl.remove_connection(conn)


#: rospy's own endpoint classes, taken before anything can replace them: ``micros-rt run`` puts
#: micros_rt's drop-in classes in ``rospy.Publisher``/``rospy.Subscriber``, and micros_rt's TCPROS
#: side must not construct those (it would call itself).
ROSPY_PUBLISHER: Any = rospy.topics.Publisher
ROSPY_SUBSCRIBER: Any = rospy.topics.Subscriber
#: the same for services: ``micros-rt run`` puts drop-in classes in ``rospy.Service``/``rospy.ServiceProxy``
ROSPY_SERVICE: Any = rospy.Service
ROSPY_SERVICE_PROXY: Any = rospy.ServiceProxy


def topic_impl(topic: str, *, publisher: bool) -> Any:
    """rospy's per-topic implementation object (what a rospy Publisher/Subscriber calls ``impl``), or None."""
    tm = get_topic_manager()
    return tm.get_publisher_impl(topic) if publisher else tm.get_subscriber_impl(topic)


def set_publisher_tcp_nodelay(topic: str) -> None:
    """rospy.Publisher(tcp_nodelay=True): TCP_NODELAY on this topic's TCPROS subscriber sockets."""
    from rospy.impl.tcpros import get_tcpros_handler

    get_tcpros_handler().set_tcp_nodelay(topic, True)


def configure_publisher_impl(impl: Any, *, headers: Optional[Dict[str, str]] = None,
                             subscriber_listener: Any = None) -> None:
    """rospy.Publisher(headers=..., subscriber_listener=...) on rospy's per-topic publisher ``impl``."""
    if impl is None:
        return
    if headers:
        impl.add_headers(headers)
    if subscriber_listener is not None:
        impl.add_subscriber_listener(subscriber_listener)  # TCPROS subscribers (rospy calls it)


def configure_subscriber_impl(impl: Any, *, buff_size: Optional[int] = None, tcp_nodelay: bool = False) -> None:
    """rospy.Subscriber(buff_size=..., tcp_nodelay=...) on rospy's per-topic subscriber ``impl`` (its TCPROS
    side reads both when it connects to a publisher)."""
    if impl is None:
        return
    if buff_size is not None:
        impl.set_buff_size(buff_size)
    if tcp_nodelay:
        impl.set_tcp_nodelay(True)


class _LatchedReplay:
    """A rospy subscriber listener: a new subscriber of a latching publisher gets each message ``messages()``
    names (oldest first) before the one rospy latches itself, which stays the latched one (unless ``messages()``
    no longer has it: its source left, and the newest of the others takes its place)."""

    def __init__(self, impl: Any, lock: Any, messages: Callable[[], List[Any]]) -> None:
        self._impl = impl
        self._lock = lock
        self._messages = messages

    def peer_subscribe(self, topic_name: str, topic_publish: Any, peer_publish: Callable[[Any], None]) -> None:
        # rospy's add_connection calls this, then sends its latched message; writing to one connection also
        # makes the message written rospy's latched one, so the newest is put back (``lock``: the owner's
        # publishing lock, so no publish() comes in between)
        with self._lock:
            current = self._messages()
            newest = self._impl.latch
            if newest is not None and not any(msg is newest for msg in current):
                newest = current[-1] if current else None   # its source is gone: the newest left is latched
            for msg in current:
                if msg is not newest:
                    peer_publish(msg)
            self._impl.latch = newest

    def peer_unsubscribe(self, topic_name: str, num_peers: int) -> None:
        pass


def replay_latched(topic: str, lock: Any, messages: Callable[[], List[Any]]) -> None:
    """Latching publisher ``topic`` sends a new TCPROS subscriber every message of ``messages()`` (taken under
    ``lock``, which the owner also holds while it publishes), then its own latched one: several latched
    messages per publisher, where rospy keeps one."""
    impl = topic_impl(topic, publisher=True)
    if impl is None or not impl.is_latch:
        raise ValueError(f"topic {topic} has no latching publisher in this process")
    impl.add_subscriber_listener(_LatchedReplay(impl, lock, messages))


def latched_messages(topic: str) -> List[Any]:
    """The last message of each latching TCPROS publisher connected to subscribed ``topic`` (rospy keeps
    it on the connection for callbacks added later)."""
    impl = topic_impl(topic, publisher=False)
    return [] if impl is None else [c.latch for c in list(impl.connections) if getattr(c, "latch", None) is not None]


def topic_connections(topic: str, *, publisher: bool) -> List[Any]:
    """rospy's connection list of ``topic`` (a copy; empty when rospy has no such endpoint)."""
    impl = topic_impl(topic, publisher=publisher)
    return [] if impl is None else list(impl.connections)


def bus_info(topic: str, *, publisher: bool) -> List[Tuple[str, str, str]]:
    """(endpoint id, transport, info) of each connection of ``topic`` in rospy's lists, as ``getBusInfo``
    sees them: the subscriber's caller id (publisher side) or the publisher's URI (subscriber side)."""
    tm = get_topic_manager()
    impl = tm.get_publisher_impl(topic) if publisher else tm.get_subscriber_impl(topic)
    if impl is None:
        return []
    return [(str(c.endpoint_id), str(getattr(c, "transport_type", TCPROS)), str(c.get_transport_info()))
            for c in list(impl.connections)]


def add_node_api_method(name: str, method: Callable[[str], List[Any]]) -> None:
    """Answer the XML-RPC method ``name(caller_id)`` on this node's API, beside ``getBusInfo``: rospy's
    server dispatches a call to the ``ROSHandler`` attribute of that name (idempotent)."""
    setattr(masterslave.ROSHandler, name, lambda self, caller_id, *_: method(caller_id))


def _request_topic(pub_uri: str, topic: str, protocols: List[List[Any]]) -> Tuple[int, str, Any]:
    """requestTopic to ``pub_uri``, retried (0.5 s, doubling, at most 8 s; for 60 s) while it times out."""
    outcome: List[Tuple[int, str, Any]] = []
    failure: List[OSError] = []

    def attempt(_: Any) -> bool:
        proxy = xmlrpc.client.ServerProxy(pub_uri, transport=TimeoutTransport(10.0), allow_none=False)
        try:
            answer: Any = proxy.requestTopic(caller_id(), topic, protocols)
            code, msg, result = answer
            outcome.append((int(code), str(msg), result))
        except OSError as exc:
            if exc.errno != errno.ECONNREFUSED:
                failure[:] = [exc]
                return False  # try again
            outcome.append((-1, f"publisher {pub_uri} unreachable: {exc}", None))
        except (xmlrpc.client.Fault, xmlrpc.client.ProtocolError, ValueError, TypeError) as exc:
            outcome.append((-1, f"publisher {pub_uri} gave a malformed requestTopic answer: {exc}", None))
        return True

    if send_with_backoff(attempt, None, 60.0, rospy.core.is_shutdown, first=0.5, most=8.0):
        return outcome[0]
    if failure and not rospy.core.is_shutdown():
        return -1, f"publisher {pub_uri} unreachable: {failure[0]}", None
    return -1, "node is shutting down", None


class _OneAtATime:
    """A lock per (topic, publisher URI) while a connection is being made, and only then.

    rospy's registration thread starts a thread per publisher URI for *every* publisher list it takes, so two
    lists that both name a new publisher (``[B]`` then ``[A, B]``, as two publishers start together) connect to
    it twice at once. Both find no connection yet; both make one; rospy keeps the second and closes the first,
    with whatever the publisher had already written into it: the publisher counted one subscriber and sent its
    first message on the connection that is then dropped (seen: 199 of 200 in
    ``test_mixed_publishers_exactly_once``; the node's log has "adding connection" twice for one URI).
    Taking turns, the second finds the first's connection and leaves it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: Dict[Tuple[str, str], List[Any]] = {}  # key -> [lock, users]

    @contextlib.contextmanager
    def turn(self, topic: str, pub_uri: str) -> Iterator[None]:
        key = (topic, pub_uri)
        with self._lock:
            entry = self._held.setdefault(key, [threading.Lock(), 0])
            entry[1] += 1
        try:
            with entry[0]:
                yield
        finally:
            with self._lock:
                entry[1] -= 1
                if not entry[1]:
                    del self._held[key]


_connecting = _OneAtATime()


def _asks_open_first(hook: SubscriptionHook, result: Any) -> str:
    """The protocol whose side reads the publisher's answer ``result`` as "open your reader first, then ask again"
    (a lazy DDS offer's answer), "" when it is an answer of another kind."""
    if not isinstance(result, list) or not result or not isinstance(result[0], str):
        return ""
    side = hook.negotiated_sides().get(result[0])
    return result[0] if side is not None and side.asks_open_first(result) else ""


def _wrapped_connect_topic(original: Callable[..., Any]) -> Callable[..., Any]:
    def _connect_topic(self: Any, topic: str, pub_uri: str) -> Any:
        with _connecting.turn(topic, pub_uri):
            return _connect_topic_now(self, topic, pub_uri)

    def _connect_topic_now(self: Any, topic: str, pub_uri: str) -> Any:
        hook = _find_subscription(topic)
        if hook is None:
            return original(self, topic, pub_uri)
        sub = get_topic_manager().get_subscriber_impl(topic)
        if not sub:
            return -1, f"No subscriber for topic [{topic}]", 0
        already = f"_connect_topic[{topic}]: subscriber already connected to publisher [{pub_uri}]"
        existing = next((c for c in list(sub.connections) if c.endpoint_id == pub_uri), None)
        if existing is not None and not _is_pseudo(existing):
            return 1, already, 0
        # An existing DDS or SHM link is asked again: the publisher may have unregistered and advertised the
        # topic anew (same node, same URI, a new DDS writer or SHM channel) faster than the old one was seen to
        # go. The offer says which peer the link holds, so that a publisher still writing there keeps it.
        held = (existing.transport_type, existing.peer_guid) if existing is not None else ("", "")
        protocols = hook.offered_protocols(held)
        if not protocols:
            return 0, "ERROR: no protocol allowed by the TransportHints", 0
        code, msg, result = _request_topic(pub_uri, topic, protocols)
        first = _asks_open_first(hook, result) if code > 0 else ""
        if first:
            # the publisher would take this transport (DDS) and this subscription has no reader of it yet (ROS 2
            # visibility off): open it and ask again; without one, ask for the rest
            hook.open_first(first)
            protocols = hook.offered_protocols(held)
            code, msg, result = _request_topic(pub_uri, topic, protocols)
            if code > 0 and _asks_open_first(hook, result):
                return 0, f"{first} reader could not be opened", 0
        if code <= 0:
            offered = [p[0] for p in protocols]
            if TCPROS not in offered:
                _log.warning(
                    "micros_rt: topic %s: publisher %s cannot use %s (%s); it is probably a stock ROS node. "
                    "Nothing is received from it: add .tcp() to the TransportHints to accept TCPROS.",
                    topic, pub_uri, "/".join(offered), short(msg, 200))
            else:
                _log.warning("micros_rt: topic %s: publisher %s refused the connection: %s", topic, pub_uri,
                             short(msg, 200))
            return code, msg, 0
        if not isinstance(result, list) or not result or not isinstance(result[0], str):
            _log.warning("micros_rt: publisher %s answered requestTopic for %s with %s; ignoring it",
                         pub_uri, topic, short(repr(result)))
            return 0, "ERROR: publisher returned invalid protocol choice", 0
        # a negotiated transport's answer: its side of the subscription reads it and connects
        side = hook.negotiated_sides().get(result[0])
        if side is not None:
            try:
                answer = side.read_answer(result[1] if len(result) > 1 else None, f"publisher {pub_uri}")
            except MalformedNegotiationError as exc:
                _log.warning("micros_rt: topic %s: publisher %s accepted %s with a malformed answer (%s); "
                             "not connected to it", topic, pub_uri, side.words, exc)
                return 0, f"malformed {result[0]} answer", 0
            if existing is not None:
                if existing.peer_guid == side.peer_of(answer):
                    return 1, already, 0
                remove_pseudo_connection(topic, existing, publisher=False)
                existing.close()
            return side.connect(pub_uri, answer)
        if existing is not None:
            return 1, already, 0  # keep the DDS or SHM link; a TCPROS answer now would be a second link
        for h in self.protocol_handlers:
            if h.supports(result[0]):
                return h.create_transport(topic, pub_uri, result)
        return 0, f"ERROR: publisher returned unsupported protocol choice: {short(repr(result))}", 0

    return _connect_topic


def _wrapped_request_topic(original: Callable[..., Any]) -> Callable[..., Any]:
    def requestTopic(self: Any, caller_id: str, topic: str, protocols: Any) -> Any:
        if not isinstance(protocols, list) or not isinstance(caller_id, str) or not isinstance(topic, str):
            return original(self, caller_id, topic, protocols)
        # resolve like rospy's _remap_table does for 'topic' before we look it up
        resolved = rospy.names.resolve_name(topic, caller_id)
        hook = _find_publication(resolved)
        negotiated = {} if hook is None else hook.negotiated_transports(caller_id)
        choice = choose_protocol(protocols, negotiated=negotiated, subscriber=short(caller_id),
                                 supports=lambda name: any(h.supports(name) for h in self.protocol_handlers),
                                 topic=short(resolved))
        for verdict in choice.declined:
            if verdict.quiet:
                _log.debug("micros_rt: %s", verdict.reason)
                continue
            _declines.warning((short(caller_id, 256), verdict.kind), verdict.reason, group=verdict.kind.split(":")[0])
        if choice.answer is not None:
            return 1, f"ready on {choice.protocol}", choice.answer.to_xmlrpc()
        if choice.entry is not None:
            return original(self, caller_id, topic, [choice.entry])
        return 0, "no supported protocol implementations", []

    requestTopic.__doc__ = original.__doc__
    return requestTopic


def transport_socket(conn: Any) -> Any:
    """The socket of a rospy TCPROS transport (also through rospy's QueuedConnection), or None."""
    for _ in range(3):
        sock = getattr(conn, "socket", None)
        if sock is not None:
            return sock
        conn = getattr(conn, "_connection", None)
        if conn is None:
            return None
    return None


class DirectQueuedConnection(QueuedConnection):  # type: ignore[misc]
    """rospy's ``QueuedConnection`` (a publisher's link with ``queue_size``: a queue of at most that many messages,
    the oldest dropped, and a thread that writes them, so that ``publish()`` never waits on a slow subscriber),
    with one change, for micros_rt's publications: a message published while the link has nothing queued and
    nothing being written is written at once, from the publishing thread, without waiting (``MSG_DONTWAIT``).
    What the socket does not take at once goes to the queue's thread as before (a partly written message's rest
    first, never dropped), so order, queue_size and a publish() that never waits are kept. roscpp writes the same
    way. rospy's hand-over to the link's thread (a Condition's notify, a ``sleep(0)``, the thread's wake-up) was
    about a third of a String's publish at 1,000 msg/s (issue 44, py-spy)."""

    _queue: List[bytes]   # rospy's (set in its __init__)

    def __init__(self, connection: Any, queue_size: int) -> None:
        self._busy = False          # the thread is writing what it took (outside the lock)
        self._rest: Optional[bytes] = None   # what the socket did not take of a message written at once
        super().__init__(connection, queue_size)

    def write_data(self, data: bytes) -> bool:
        conn = self._connection
        with self._lock:
            if self._error is None and not self._queue and not self._busy and self._rest is None:
                sock = getattr(conn, "socket", None)
                if sock is not None and not conn.done and sock.gettimeout() is None:
                    try:
                        sent = sock.send(data, socket.MSG_DONTWAIT)
                    except (BlockingIOError, InterruptedError):
                        sent = 0
                    except OSError:
                        sent = 0    # the thread's write raises it and closes the link, as rospy's does
                    if sent == len(data):
                        conn.stat_bytes += sent
                        conn.stat_num_msg += 1
                        return True
                    if sent:
                        conn.stat_bytes += sent
                        self._rest = bytes(memoryview(data)[sent:])
                        self._cond_data_available.notify()
                        return True
        return bool(super().write_data(data))

    def _run(self) -> None:
        conn = self._connection
        while not conn.done:
            with self._lock:
                self._busy = False
                while not self._queue and self._rest is None and not conn.done:
                    self._cond_data_available.wait()
                items: List[bytes] = [] if self._rest is None else [self._rest]
                items += self._queue
                self._rest, self._queue = None, []
                self._busy = bool(items)
            for data in items:
                try:
                    conn.write_data(data)
                except Exception as exc:  # as rospy's: raised by the next write_data
                    with self._lock:
                        self._error = exc
        with self._lock:
            self._busy = False


def _queued_connection(connection: Any, queue_size: int) -> Any:
    """What ``_PublisherImpl.add_connection`` wraps a subscriber's link in: :class:`DirectQueuedConnection` for
    micros_rt's publications, rospy's own ``QueuedConnection`` for any other publisher of the process."""
    if _find_publication(getattr(connection, "name", "") or "") is not None:
        return DirectQueuedConnection(connection, queue_size)
    return QueuedConnection(connection, queue_size)


def _wrapped_publisher_add_connection(original: Callable[..., Any]) -> Callable[..., Any]:
    # Publisher side: every accepted TCPROS subscriber link passes here (before rospy wraps it in a
    # QueuedConnection); micros_rt publications mark the socket with their transport priority.
    def add_connection(self: Any, c: Any) -> Any:
        hook = _find_publication(getattr(self, "resolved_name", ""))
        if hook is not None and not _is_pseudo(c):  # a negotiated transport's link is no socket
            try:
                hook.on_tcpros_connection(c, transport_socket(c))
            except Exception:
                _log.warning("micros_rt: topic %s: could not mark a TCPROS connection", self.resolved_name,
                             exc_info=True)
        return original(self, c)

    add_connection.__doc__ = original.__doc__
    return add_connection


class MasterWatch:
    """Notices a ROS master that went away or restarted, and re-registers this node with it.

    rospy registers once; after a master restart the node is invisible (no new connections,
    ``rosnode list`` misses it). Data already flowing keeps flowing meanwhile: DDS needs no
    master at all, and TCPROS links stay up.

    Cheap on the master and on this node: an idle TCP connection to the master's port stays open (the
    master's server thread for it waits in ``recv``, costing nothing), and the kernel reports its close when
    the master's process ends (TCP keep-alive probes, sent by the kernel, when its host goes silent). Each
    ``period`` is one local ``poll`` of that socket; only when it closed does the watch connect again, and it
    asks the master's pid (``getPid``) when it answers again, to tell a restart from a pause. A TCP connect
    per node per second (the way until now) cost the master 1.1-1.5 % of a core in a graph of 30 nodes.
    """

    #: kernel keep-alive on the watch connection: first probe after this idle time, then every
    #: KEEPALIVE_INTERVAL, dead after KEEPALIVE_COUNT unanswered (a master host that vanished)
    KEEPALIVE_IDLE, KEEPALIVE_INTERVAL, KEEPALIVE_COUNT = 10, 5, 2

    def __init__(self, uri: Optional[str] = None, period: float = 1.0) -> None:
        self.uri = uri or str(rosgraph.get_master_uri())
        self.period = period
        self._next = 0.0
        self._pid: Optional[int] = None
        self._down_since: Optional[float] = None
        self._conn: Optional[socket.socket] = None
        parsed = urllib.parse.urlparse(self.uri)
        self._address = (parsed.hostname or "localhost", parsed.port or 11311)

    def _connect(self) -> Optional[socket.socket]:
        try:
            conn = socket.create_connection(self._address, timeout=1.0)
        except OSError:
            return None
        conn.setblocking(False)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for option, value in (("TCP_KEEPIDLE", self.KEEPALIVE_IDLE), ("TCP_KEEPINTVL", self.KEEPALIVE_INTERVAL),
                              ("TCP_KEEPCNT", self.KEEPALIVE_COUNT)):
            if hasattr(socket, option):
                conn.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)
        return conn

    def _still_open(self, conn: socket.socket) -> bool:
        """The master never writes on the watch connection: readable means closed (EOF or reset)."""
        try:
            readable, _, _ = select.select([conn], [], [], 0)
            if not readable:
                return True
            return bool(conn.recv(1, socket.MSG_PEEK))
        except (OSError, ValueError):
            return False

    def _master(self) -> Any:
        """A proxy of the master whose calls wait 2 s at most (the watch's two questions)."""
        return xmlrpc.client.ServerProxy(self.uri, transport=TimeoutTransport(2.0))

    def _master_pid(self) -> Optional[int]:
        proxy = self._master()
        try:
            answer: Any = proxy.getPid(caller_id())
            code, _msg, pid = answer
            return int(pid) if code == 1 else None
        except (OSError, xmlrpc.client.Error, ValueError, TypeError):
            return None

    def close(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()

    def check(self) -> None:
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + self.period
        if self._conn is not None:
            if self._still_open(self._conn):
                return  # up, as it was
            self.close()
        self._conn = self._connect()
        pid = self._master_pid() if self._conn is not None else None
        if pid is None:
            self.close()  # reachable but not answering (starting, or not a master): ask again next time
            if self._down_since is None:
                self._down_since = now
                _log.warning("micros_rt: the ROS master at %s does not answer; connections already made keep "
                             "delivering (DDS needs no master), new ones wait for it", self.uri)
            return
        restarted = self._pid is not None and pid != self._pid
        back = self._down_since is not None
        self._pid = pid
        self._down_since = None
        if restarted or (back and not self._knows_this_node()):
            counts = reregister_all()
            _log.warning("micros_rt: the ROS master at %s is back%s; re-registered %d publications, "
                         "%d subscriptions and %d services", self.uri, " (restarted)" if restarted else "",
                         *counts)
        elif back:  # slow, not gone (a host busy starting many nodes): its registrations stand
            _log.info("micros_rt: the ROS master at %s answers again; it still has this node's registrations",
                      self.uri)

    def _knows_this_node(self) -> bool:
        """The master (back after not answering) still has this node at this node's URI: it was slow or paused,
        not restarted, and re-registering every topic would only add to its load (60 nodes starting at once kept
        a master too busy to answer in 2 s, and each node that re-registered then made it busier). A master
        restarted with the same pid (its container's first process) does not know the node: re-registered."""
        proxy = self._master()
        try:
            answer: Any = proxy.lookupNode(caller_id(), caller_id())
            code, _msg, uri = answer
            return code == 1 and str(uri) == str(rospy.core.get_node_uri())
        except (OSError, xmlrpc.client.Error, ValueError, TypeError):
            return False


def _reg_manager() -> Any:
    for listener in get_registration_listeners().listeners:
        if isinstance(listener, RegManager):
            return listener
    return None


def connect_again(topic: str, pub_uri: str, done: Callable[[int, str], None]) -> None:
    """Ask publisher ``pub_uri`` of ``topic`` for a link again, on a thread of its own, as rospy's TCPROS
    subscriber reconnects a dropped connection by itself; ``done(code, message)`` then (code 1: linked)."""
    reg = _reg_manager()
    handler = getattr(reg, "handler", None)
    if handler is None or getattr(handler, "done", True) or rospy.is_shutdown():
        return

    def run() -> None:
        try:
            code, msg, _ = handler._connect_topic(topic, pub_uri)
        except Exception as exc:  # the publisher's process went meanwhile: what rospy's own thread does
            code, msg = 0, f"{type(exc).__name__}: {exc}"
        if not rospy.is_shutdown():
            done(int(code), str(msg))

    threading.Thread(target=run, name=f"micros_rt reconnect {short(topic, 40)}", daemon=True).start()


def reregister_all() -> Tuple[int, int, int]:
    """Register every publication, subscription and service of this node again with the master."""
    reg = _reg_manager()
    if reg is None:
        return 0, 0, 0
    tm = get_topic_manager()
    pubs = tm.get_publications()
    subs = tm.get_subscriptions()
    srvs = get_service_manager().get_services()
    for name, type_ in pubs:
        reg.reg_added(name, type_, Registration.PUB)
    for name, type_ in subs:
        reg.reg_added(name, type_, Registration.SUB)  # also connects to the publishers it returns
    for name, uri in srvs:
        reg.reg_added(name, uri, Registration.SRV)
    return len(pubs), len(subs), len(srvs)


class _PromptPoll:
    """``time`` as ``rospy.impl.init`` sees it while a node starts, with a finer registration poll.

    ``start_node`` checks whether the master registration is done, and if not sleeps 0.1 s. The
    registration takes a few milliseconds on a local master, so whenever the first check came too
    early a node's start lost ~95 ms (measured: ``init_node`` 10 ms or 110 ms, run to run). Here the
    sleeps start at 2 ms and double up to rospy's 0.1 s, so a master that is down costs no more
    wake-ups than before."""

    def __init__(self) -> None:
        self._step = 0.002

    def __getattr__(self, name: str) -> Any:
        return getattr(time, name)

    def sleep(self, seconds: float) -> None:
        if seconds < self._step:
            time.sleep(seconds)
            return
        time.sleep(self._step)
        self._step = min(self._step * 2, seconds)


@contextlib.contextmanager
def prompt_registration_poll() -> Iterator[None]:
    """Within this block, ``rospy.init_node`` notices its master registration within milliseconds."""
    module: Any = rospy.impl.init
    original = module.time
    module.time = _PromptPoll()
    try:
        yield
    finally:
        module.time = original


def _merging_publisher_update(self: Any, resolved_name: str, uris: List[str]) -> None:
    """rospy's ``RegManager.publisher_update``, except that an update does not erase one still queued for the
    same topic.

    rospy's registration thread takes the newest queued update of a topic and discards the older ones. Under
    load the publisher list that ``registerSubscriber`` returned (read before a publisher registered) can be
    queued *after* the master's ``publisherUpdate`` that names the new publisher; the stale list then erases it
    and the subscriber never connects to that publisher (measured: a 60-node graph starting on 2 cores, in 1
    run of 3-5; the master's log shows the update delivered, the node's log no connection attempt). rospy only
    ever connects on an update (a publisher that goes away closes its connection), so the union of the queued
    lists loses nothing: a URI that is no longer a publisher answers ``requestTopic`` with an error."""
    with self.cond:
        queued = [uri for topic, pending in self.updates if topic == resolved_name for uri in pending or ()]
        self.updates.append((resolved_name, list(dict.fromkeys([*(uris or ()), *queued]))))
        self.cond.notify_all()


def install(find_publication: Callable[[str], Optional[PublicationHook]],
            find_subscription: Callable[[str], Optional[SubscriptionHook]]) -> None:
    """Wrap rospy's negotiation once per process (idempotent); hooks are looked up by resolved topic
    name through the two functions (the endpoint registry owns the endpoints)."""
    global _installed, _find_publication, _find_subscription
    with _install_lock:
        _find_publication, _find_subscription = find_publication, find_subscription
        if _installed:
            return
        handler_cls = masterslave.ROSHandler
        handler_cls._connect_topic = _wrapped_connect_topic(handler_cls._connect_topic)
        handler_cls.requestTopic = _wrapped_request_topic(handler_cls.requestTopic)
        pub_cls = rospy.topics._PublisherImpl
        pub_cls.add_connection = _wrapped_publisher_add_connection(pub_cls.add_connection)
        pub_cls.has_connection = _publisher_has_connection
        rospy.topics.QueuedConnection = _queued_connection   # the name add_connection uses
        rospy.impl.registration.RegManager.publisher_update = _merging_publisher_update
        _installed = True
