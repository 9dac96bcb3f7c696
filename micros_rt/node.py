"""init_node, NodeHandle and the node's lifetime: rospy's API with QoS and a DDS data plane.

Each micros_rt publication owns a rospy publisher (master registration, TCPROS
for stock peers) and, when DDS is available, one DataWriter
(:mod:`micros_rt.core.publication`). Each subscription owns a rospy subscriber and,
when its TransportHints allow DDS, a DataReader (:mod:`micros_rt.core.subscription`).
Which one carries data from a given publisher is decided per publisher in
``requestTopic`` (see :mod:`micros_rt.transports.tcpros.patches`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import os
import threading
import time
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple, Type, Union

import genpy
import rospy

from .core import introspection as _introspection
from .transports.tcpros import patches
from .core.publication import Publisher, _Publication
from .core import negotiated
from .transports.builtin import builtin_transports, inbox_for
from .transports.negotiated import PublicationSide
from .core.runtime import _graph_id, _log, _node, _require_node
from .transports.dds import process as dds_process
from .transports.dds.host_gateway import WAKE as ros2_wake, endpoint_descriptions
from .core.reader_subscription import OpenReader, ReaderSubscription
from .core.registry import EndpointRegistry
from .core.subscription import DeadlineMissed, Subscriber, _Subscription
from .log import flush as flush_logs
from . import settings
from .transports.base import ProfileBackend, close_profile_backends, profile_backends
from .transports.pacing import LinkPacer
from .qos.links import send_buffer_below_high
from .transports.dds.participant import close_participant
from .transports.shm.host import close_node as close_shm_node
from .exceptions import NodeNotInitializedError, QoSTypeError
from .negotiation.hints import TransportHints
from .negotiation.decide import Verdict
from .negotiation.protocol import DDS, SHM, TCPROS
from .qos import (
    AdvertiseQoSOptions,
    QoSProfile,
    SubscribeQoSOptions,
    TransportPriority,
    merge_advertise,
    merge_subscribe,
    to_seconds,
)

__all__ = [
    "init_node",
    "spin",
    "is_shutdown",
    "ok",
    "shutdown",
    "NodeHandle",
    "Publisher",
    "Subscriber",
    "DeadlineMissed",
    "NodeInfo",
    "node_info",
]


def init_node(name: str, argv: Optional[List[str]] = None, anonymous: bool = False, *,
              qos_profile: Union[str, "os.PathLike[str]", QoSProfile, None] = None, **kwargs: Any) -> None:
    """Start this process's ROS node, like ``rospy.init_node``, with micros_rt negotiation.

    ``qos_profile``: per-topic QoS applied without code changes, a :class:`~micros_rt.QoSProfile` or the path
    of its YAML file (else the file ``MICROS_RT_QOS_PROFILE`` names, if any). A ``MICROS_RT_*`` variable with
    a bad value raises :class:`~micros_rt.SettingError` (:mod:`micros_rt.settings`).

    >>> micros_rt.init_node("talker", anonymous=True)   # doctest: +SKIP
    >>> micros_rt.init_node("talker", qos_profile=micros_rt.QoSProfile.from_string("ros2: false"))  # doctest: +SKIP
    """
    settings.check()  # a mistyped MICROS_RT_* variable stops the node here, in words, before anything starts
    patches.install(_node.publications.get, _node.subscriptions.get)
    _introspection.install(lambda: _node)
    profile = _profile(qos_profile)
    _tune_malloc()
    dds_process.start_early(profile)
    with patches.prompt_registration_poll():
        rospy.init_node(name, argv=argv, anonymous=anonymous, **kwargs)
    with _node.lock:
        _node.initialized = True
        _node.profile = profile
        _node.pacer = LinkPacer(profile.links) if profile is not None and profile.links else None
        _node.graph = _graph_id()
    rospy.on_shutdown(_close_all)
    threading.Thread(target=_housekeeping_loop, name="micros_rt housekeeping", daemon=True).start()


def _profile(given: Union[str, "os.PathLike[str]", QoSProfile, None]) -> Optional[QoSProfile]:
    """The node's profile: ``given``, the file it names, or the file ``MICROS_RT_QOS_PROFILE`` names."""
    if isinstance(given, QoSProfile):
        return given
    path = given or settings.QOS_PROFILE.get()
    return QoSProfile.load(path) if path else None


def _tune_malloc() -> None:
    """glibc malloc settings for a node that moves big messages through many threads (once, at init).

    - Arenas capped (default 2, ``MICROS_RT_MALLOC_ARENA_MAX``; 0 leaves glibc's default). rospy answers
      every XML-RPC call on a new thread, and glibc gives threads arenas of their own (up to 8 per core)
      that keep their high-water mark: 10,000 requestTopic calls raised a node's RSS by 13 MB and it kept
      creeping ~2.5 MB per 10,000 more (a stock rospy node: +15-20 MB). With two arenas: +4 MB, then flat.
      Set before rospy starts its threads; arenas made later obey it.
    - Large blocks stay in the heap (``M_MMAP_THRESHOLD`` 32 MB, ``M_TRIM_THRESHOLD`` 128 MB;
      ``MICROS_RT_MALLOC_KEEP_LARGE=0`` leaves glibc's defaults). Each 6.2 MB Image is a few buffers of
      its size (Cyclone's reassembly, the sample's bytes, the decoded field); with glibc's defaults they
      were mmap'd and unmapped, or trimmed, per message, and the kernel faulted and zeroed every page
      again: perf showed a third of the subscriber's time in page faults, 6.4 ms of CPU per 1920x1080
      Image. Reused from the heap: 2.0-2.5 ms, and 43 -> 62-136 Images/s. A node that once held big
      messages keeps that memory for the next ones, as a stock rospy node's socket buffers do.
    """
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return  # not glibc: nothing to tune
    arenas = settings.MALLOC_ARENA_MAX.get()
    if arenas > 0:
        mallopt(ctypes.c_int(-8), ctypes.c_int(arenas))  # M_ARENA_MAX
    if settings.MALLOC_KEEP_LARGE.get():
        mallopt(ctypes.c_int(-3), ctypes.c_int(32 << 20))   # M_MMAP_THRESHOLD (glibc's maximum)
        mallopt(ctypes.c_int(-1), ctypes.c_int(128 << 20))  # M_TRIM_THRESHOLD


#: Seconds between the node's housekeeping ticks (master watch, publishers' bookkeeping, the ROS 2 watch)
HOUSEKEEPING_PERIOD = 0.5


def _housekeeping_loop() -> None:
    # Publisher-side bookkeeping that no data event drives: subscribers gone from DDS;
    # and the master: rospy never re-registers after a master restart, micros_rt does.
    watch = patches.MasterWatch()
    while not rospy.is_shutdown():
        try:
            watch.check()
        except Exception:
            _log.exception("micros_rt: checking the ROS master failed (will retry)")
        now = time.monotonic()
        if _node.pacer is not None:
            try:
                _node.pacer.rebalance()
            except Exception:
                _log.exception("micros_rt: sharing the profile's links among TCPROS connections failed (will retry)")
        for p in _node.publications.all():
            try:
                p.housekeeping(now)
            except Exception:
                _log.exception("micros_rt: topic %s: publisher housekeeping failed (will retry)", p.topic)
        try:
            if not rospy.is_shutdown() and dds_process.watch_ros2(
                    _node.profile, patches.caller_id(),
                    lambda: endpoint_descriptions(_node.publications.all(), _node.subscriptions.all())):
                _open_dds_sides()
        except Exception:
            _log.exception("micros_rt: watching the DDS domain for ROS 2 nodes failed (will retry)")
        # one wake per tick: an idle node's ticks are most of its CPU in a graph of many nodes (a wake of a
        # Python thread costs ~0.1 ms here; two per tick were 0.84 ms/s per node of a 10 Hz ring)
        ticked = time.monotonic()
        if ros2_wake.wait(HOUSEKEEPING_PERIOD):  # the host's ROS 2 gateway (this node watching): an endpoint
            ros2_wake.clear()                    # appeared on DDS; the next tick comes sooner (>= 0.1 s apart)
            time.sleep(max(0.0, 0.1 - (time.monotonic() - ticked)))


class NodeInfo(NamedTuple):
    """What programs built on micros_rt (the bridges, the relay) need to know of this process's node."""

    name: str                        #: the node's resolved name (rospy's caller id)
    graph: str                       #: this ROS graph's identity (the master's run_id and URI)
    profile: Optional[QoSProfile]    #: the YAML profile given to init_node, if any


def node_info() -> NodeInfo:
    """This process's node; raises NodeNotInitializedError before :func:`init_node`."""
    if not _node.initialized:
        raise NodeNotInitializedError("call micros_rt.init_node(name) first")
    return NodeInfo(patches.caller_id(), _node.graph, _node.profile)


def spin() -> None:
    """Block until the node shuts down (Ctrl-C or :func:`shutdown`)."""
    rospy.spin()


def is_shutdown() -> bool:
    return bool(rospy.is_shutdown())


def ok() -> bool:
    """True while the node runs (the opposite of :func:`is_shutdown`)."""
    return not rospy.is_shutdown()


def shutdown(reason: str = "micros_rt.shutdown() called") -> None:
    """Stop the node: unregister every topic, release DDS entities and threads."""
    rospy.signal_shutdown(reason)
    _close_all()


#: How long a shutdown on the main thread waits for the closing before it lets the interrupted code go on.
SHUTDOWN_WAIT = 1.0
_closer: Optional[threading.Thread] = None
_closer_lock = threading.Lock()  # held for a few bytecodes only, never across a wait


def _close_all() -> None:
    """Close every topic, transport and the DDS and SHM planes, on a thread of its own.

    rospy runs its shutdown hooks in whatever thread calls ``signal_shutdown``: for SIGINT and SIGTERM that is
    the main thread, interrupted at any bytecode, perhaps inside a publish() that holds a lock the closing
    needs (issue 46: ``ShmChannel.try_send`` held its channel's lock and the hook waited for it in the same
    thread, for ever). On the main thread the hook therefore waits at most :data:`SHUTDOWN_WAIT` for the
    closing and then lets the interrupted code go on, which lets go of its lock; the closing thread is not a
    daemon, so the interpreter waits for it to finish before it exits."""
    global _closer
    with _closer_lock:
        closer = _closer
        if closer is None or not closer.is_alive():
            closer = _closer = threading.Thread(target=_close_logged, name="micros_rt shutdown")
            closer.start()
    main = threading.current_thread() is threading.main_thread()
    closer.join(SHUTDOWN_WAIT if main else None)


def _close_logged() -> None:
    try:
        _close_everything()
    except Exception:  # rospy's own shutdown may run beside it: say what failed, the process still ends
        _log.exception("micros_rt: closing the node failed")


def _close_everything() -> None:
    dds_process.wait_started()
    _node.publications.close_all()
    _node.subscriptions.close_all()
    close_profile_backends()  # MQTT: disconnect cleanly now, not at interpreter exit
    dds_process.close()  # the watch (another node of the host takes it over at its next tick), the back end
    close_participant()
    close_shm_node()  # after every channel and link: iceoryx2's files go with the node
    flush_logs()


# ---------------------------------------------------------------------------


QoSArg = Union[TransportPriority, AdvertiseQoSOptions, float, int, Any]


class NodeHandle:
    """rospy's publish/subscribe with micros_rt's QoS, names resolved relative to ``namespace``.

    >>> nh = NodeHandle()                                                  # doctest: +SKIP
    >>> pub = nh.advertise_with_qos("chatter", String, 10, TransportPriority.HIGH)  # doctest: +SKIP
    """

    def __init__(self, namespace: str = "") -> None:
        if not isinstance(namespace, str):
            raise TypeError(f"namespace must be a str, got {type(namespace).__name__}")
        self.namespace = namespace

    def resolve_name(self, name: str) -> str:
        """Resolve ``name`` like rospy (remappings, ``~private``, ``__ns``), inside this handle's namespace."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"topic name must be a non-empty str, got {name!r}")
        if self.namespace and not name.startswith(("/", "~")):
            ns = self.namespace
            if ns.startswith("~"):
                ns = rospy.names.resolve_name(ns)
            name = ns.rstrip("/") + "/" + name
        return str(rospy.resolve_name(name))

    # publishers -----------------------------------------------------------
    def advertise(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int], *,
                  latch: bool = False) -> Publisher:
        """Like ``rospy.Publisher``; QoS comes from the YAML profile if one names the topic."""
        return self._advertise(topic, data_class, queue_size, None, latch)

    def advertise_with_qos(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                           qos: QoSArg, *, latch: bool = False) -> Publisher:
        """Advertise with QoS: a :class:`TransportPriority`, a latency budget (seconds or
        ``rospy.Duration``) or an :class:`AdvertiseQoSOptions` (micROS RT's three variations)."""
        if isinstance(qos, AdvertiseQoSOptions):
            options = qos
        elif isinstance(qos, TransportPriority):
            options = AdvertiseQoSOptions(transport_priority=qos)
        elif isinstance(qos, bool):
            raise QoSTypeError(f"qos={qos!r} is invalid: expected TransportPriority, a latency budget "
                               "(seconds or rospy.Duration) or AdvertiseQoSOptions")
        elif isinstance(qos, (int, float)) or hasattr(qos, "to_sec"):
            options = AdvertiseQoSOptions(latency_budget=to_seconds(qos, "latency_budget"))
        else:
            raise QoSTypeError(f"qos={qos!r} is invalid: expected TransportPriority, a latency budget "
                               "(seconds or rospy.Duration) or AdvertiseQoSOptions")
        return self._advertise(topic, data_class, queue_size, options, latch)

    def _advertise(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                   options: Optional[AdvertiseQoSOptions], latch: bool) -> Publisher:
        _require_node()
        _check_data_class(data_class)
        if not isinstance(latch, bool):
            raise TypeError(f"latch must be True or False, got {latch!r}")
        resolved = self.resolve_name(topic)
        profile = _node.profile.advertise_options(resolved) if _node.profile else None
        effective = merge_advertise(options, profile)

        def reuse(pub: _Publication) -> None:
            if pub.data_class is not data_class:
                raise rospy.ROSException(
                    f"topic {resolved} is already advertised in this node with type {pub.data_class._type}")
            if pub.options != effective or pub.latch != latch:
                _log.warning("micros_rt: topic %s is already advertised in this node with %s (latch=%s); "
                             "the new Publisher shares it", resolved, pub.options, pub.latch)

        node_profile = _node.profile
        served = node_profile.advertise_transports(resolved) if node_profile else None

        def refusal(protocol: str) -> Optional[Verdict]:
            # the profile's transport_hints may keep the topic off a negotiated transport: subscribers hear why
            if node_profile is None or served is None or protocol in served:
                return None
            return Verdict(False, "profile", f"topic {resolved}: the publisher's profile ({node_profile.source}) "
                                             f"keeps it off {protocol} (transport_hints: [{', '.join(served)}]); "
                                             f"the subscriber's next protocol is used")

        def create() -> _Publication:
            # the negotiated transports' sides, in the registry's order (core/negotiated.py)
            sides = tuple(_publication_side(t, refusal(name)) for name, t in negotiated.TRANSPORTS.items())
            return _Publication(resolved, data_class, queue_size, latch, effective, tag=_tag(), sides=sides,
                                extra=_profile_backends(), pacer=_node.pacer)

        pub = _node.publications.acquire(resolved, create, reuse)
        return Publisher(pub, _node.publications)

    # subscribers ----------------------------------------------------------
    def subscribe(self, topic: str, data_class: Type[genpy.Message], callback: Callable[..., None],
                  queue_size: Optional[int] = None, transport_hints: Optional[TransportHints] = None, *,
                  callback_args: Any = None) -> Subscriber:
        """Like ``rospy.Subscriber``, with :class:`TransportHints` choosing DDS/TCPROS order."""
        if transport_hints is not None and not isinstance(transport_hints, TransportHints):
            raise TypeError(f"transport_hints must be micros_rt.TransportHints, got {transport_hints!r}")
        return self._subscribe(topic, data_class, callback, queue_size, None, transport_hints, callback_args)

    def subscribe_with_qos(self, topic: str, data_class: Type[genpy.Message], callback: Callable[..., None],
                           queue_size: Optional[int], qos: SubscribeQoSOptions,
                           transport_hints: Optional[TransportHints] = None, *,
                           callback_args: Any = None, msg_valid_period: float = math.inf) -> Subscriber:
        """Subscribe with :class:`SubscribeQoSOptions`; shared memory or DDS is preferred, TCPROS is the fallback
        (``transport_hints`` choose, as for :meth:`subscribe`).
        ``msg_valid_period``: this subscriber's own lifespan (seconds): a message older than that by its
        source stamp (the DDS write time, or its Header stamp over TCPROS) is dropped and counted in
        ``dropped_expired``, whatever the publisher offers (the shorter applies)."""
        if not isinstance(qos, SubscribeQoSOptions):
            raise QoSTypeError(f"qos={qos!r} is invalid: expected micros_rt.SubscribeQoSOptions")
        if transport_hints is not None and not isinstance(transport_hints, TransportHints):
            raise TypeError(f"transport_hints must be micros_rt.TransportHints, got {transport_hints!r}")
        return self._subscribe(topic, data_class, callback, queue_size, qos, transport_hints, callback_args,
                               to_seconds(msg_valid_period, "msg_valid_period"))

    def subscribe_reader(self, name: str, data_class: Type[genpy.Message], open_reader: OpenReader,
                         callback: Callable[..., None], queue_size: Optional[int],
                         qos: Optional[SubscribeQoSOptions] = None, *, msg_valid_period: float = math.inf,
                         callback_args: Any = None) -> Subscriber:
        """Deliver the messages of a transport reader a program opened itself (a bridge's link) to
        ``callback`` through the same admission path as any subscription: ``qos``'s time filter and
        deadline, ``msg_valid_period`` (dropped when older by their source stamp), ``queue_size`` (the
        newest kept), counted in ``statistics()``. ``open_reader(depth, wake)`` opens the reader (a
        :class:`micros_rt.transports.base.PushReader`). ``name`` names it in logs and ``DeadlineMissed``;
        nothing is registered with the master. ``unregister()`` closes it."""
        _check_subscriber(data_class, callback)
        if qos is not None and not isinstance(qos, SubscribeQoSOptions):
            raise QoSTypeError(f"qos={qos!r} is invalid: expected micros_rt.SubscribeQoSOptions or None")
        lifespan = to_seconds(msg_valid_period, "msg_valid_period")
        registry: EndpointRegistry[_Subscription] = EndpointRegistry("reader subscription")

        def create() -> _Subscription:
            new = ReaderSubscription(name, data_class, open_reader, queue_size, qos, graph=_node.graph,
                                     lifespan=lifespan)
            new.callbacks = ((callback, callback_args),)
            return new

        sub = registry.acquire(name, create, lambda _existing: None)
        return Subscriber(sub, registry, callback, callback_args)

    def _subscribe(self, topic: str, data_class: Type[genpy.Message], callback: Callable[..., None],
                   queue_size: Optional[int], options: Optional[SubscribeQoSOptions],
                   code_hints: Optional[TransportHints], callback_args: Any,
                   lifespan: float = math.inf) -> Subscriber:
        _check_subscriber(data_class, callback)
        resolved = self.resolve_name(topic)
        profile = _node.profile.subscribe_options(resolved) if _node.profile else None
        effective = merge_subscribe(options, profile) if (options or profile) else None
        # TransportHints given in code win; else the profile's transport_hints; else DDS, then TCPROS
        hints = code_hints or TransportHints()
        if code_hints is None and _node.profile is not None:
            order = _node.profile.subscribe_transports(resolved)
            if order is not None:
                hints = TransportHints.from_names(order)

        def reuse(sub: _Subscription) -> None:
            if sub.data_class is not data_class:
                raise rospy.ROSException(
                    f"topic {resolved} is already subscribed in this node with type {sub.data_class._type}")
            if sub.options != effective or sub.hints != hints or sub.lifespan != lifespan:
                _log.warning("micros_rt: topic %s is already subscribed in this node with %s, %r, msg_valid_period "
                             "%g; the new Subscriber shares them", resolved, sub.options, sub.hints, sub.lifespan)

        created: List[_Subscription] = []

        def create() -> _Subscription:
            # the negotiated transports the hints allow (core/negotiated.py); with ROS 2 visibility off, the DDS
            # reader comes with the first publisher that takes DDS
            dds = dds_backend() if dds_process.ros2_visible(_node.profile) and hints.allows_dds else None
            sides = {name: t.subscription for name, t in negotiated.TRANSPORTS.items()}
            inbox = inbox_for(dds=dds, allows_shm=hints.allows_shm)
            new = _Subscription(resolved, data_class, queue_size, effective, hints, inbox=inbox, tag=_tag(),
                                graph=_node.graph, sides=sides, extra=_profile_backends(), lifespan=lifespan)
            new.callbacks = ((callback, callback_args),)  # before start(): a latched message may come at once
            created.append(new)
            return new

        sub = _node.subscriptions.acquire(resolved, create, reuse)
        if not created:
            with sub.lock:
                sub.callbacks = sub.callbacks + ((callback, callback_args),)
            sub.replay_latched(callback, callback_args)  # a new subscriber of a latched topic gets its message
        return Subscriber(sub, _node.subscriptions, callback, callback_args)

    # services -------------------------------------------------------------
    def advertise_service(self, service: str, srv_class: Any, handler: Callable[[Any], Any], *,
                          ros2: bool = True) -> "ServiceServer":
        """Like ``rospy.Service`` (roscpp's ``advertiseService``): ``handler(request)`` answers stock ROS 1 clients
        over TCPROS and, with ``ros2=True``, ROS 2 clients (``rclpy`` ``create_client``) of the same name over
        DDS. ``shutdown()`` on the answer withdraws it. See docs/services.md."""
        from .services import advertise_service

        return advertise_service(self.resolve_name(service), srv_class, handler, ros2=ros2)

    def service_client(self, service: str, srv_class: Any, *, timeout: Optional[float] = None,
                       ros2: bool = True) -> "ServiceClient":
        """A callable like ``rospy.ServiceProxy`` (with ``wait_for_service(timeout)``) that reaches a ROS 1 server
        through the master or, with ``ros2=True``, a ROS 2 server through DDS discovery; ``timeout`` bounds each
        call (seconds, None: wait for ever). See docs/services.md."""
        from .services import service_client

        return service_client(self.resolve_name(service), srv_class, timeout=timeout, ros2=ros2)

    # actions --------------------------------------------------------------
    def offer_action_to_ros2(self, name: str, action_class: Any, *, ros2_type: Optional[str] = None,
                             accept_timeout: float = 5.0) -> "ActionToRos2":
        """Make the ROS 1 (actionlib) action server at ``name`` reachable by ROS 2 action clients: an rclpy action
        server of the same name forwards their goals, cancels, feedback and results. ``action_class`` is what
        actionlib takes (``FibonacciAction``); its ROS 2 type is ``pkg/action/Fibonacci`` unless ``ros2_type`` says
        otherwise. A goal the ROS 1 server does not acknowledge within ``accept_timeout`` seconds is rejected.
        See docs/actions.md."""
        from .actions import offer_action_to_ros2

        return offer_action_to_ros2(self.resolve_name(name), action_class, ros2_type=ros2_type,
                                    accept_timeout=accept_timeout)

    def offer_ros2_action(self, name: str, action_class: Any, *, ros2_type: Optional[str] = None,
                          accept_timeout: float = 5.0) -> "ActionFromRos2":
        """Make the ROS 2 action server of ``name`` reachable by ROS 1 (actionlib) clients: an actionlib server of
        the same name in this process forwards their goals and cancels to it, and its feedback and results back.
        A goal the ROS 2 server does not answer within ``accept_timeout`` seconds is rejected in words.
        See docs/actions.md."""
        from .actions import offer_ros2_action

        return offer_ros2_action(self.resolve_name(name), action_class, ros2_type=ros2_type,
                                 accept_timeout=accept_timeout)


from typing import TYPE_CHECKING  # noqa: E402  (kept beside the service methods)

if TYPE_CHECKING:  # the services and actions packages are imported on first use
    from .actions import ActionFromRos2, ActionToRos2
    from .transports.dds.backend import DDSBackend
    from .services import ServiceClient, ServiceServer


def _open_dds_sides() -> None:
    """ROS 2 was seen (``auto`` visibility): every topic's DDS writer and reader now, as visibility on makes them
    with the topic; the links negotiated before stay as they are."""
    opened = 0
    for pub in _node.publications.all():
        writer = pub.sides.get(DDS)
        if writer is not None and writer.open_now():
            opened += 1
    for sub in _node.subscriptions.all():
        reader = sub.sides.get(DDS)
        if reader is not None and reader.open_first():
            opened += 1
    _log.info("micros_rt: ROS 2 is on the DDS domain: this node's topics are ROS 2 topics now (%d DDS writers and "
              "readers)", opened)


def dds_backend() -> "Optional[DDSBackend]":
    """The DDS back end of this process (created with the participant), or None without DDS."""
    profile = _node.profile
    return dds_process.backend(lambda: str(rospy.get_caller_id()),
                               lambda: None if profile is None else send_buffer_below_high(profile.links))


# a topic waits for the DDS import init_node started; microsRtInfo shows the process's DDS
_node.before_topic = dds_process.wait_started
_node.dds_info = dds_process.info
# the node's own negotiated transports, first in the registry's order (a program's come after them)
negotiated.install_builtin(builtin_transports(dds_backend=dds_backend,
                                              visible=lambda: dds_process.ros2_visible(_node.profile)))


def _publication_side(transport: negotiated.NegotiatedTransport,
                      refusal: Optional[Verdict]) -> Callable[[_Publication], PublicationSide]:
    return lambda pub: transport.publication(pub, refusal)


def _profile_backends() -> Tuple[ProfileBackend, ...]:
    """The back ends (MQTT) the node's YAML profile attaches to topics beside DDS/TCPROS."""
    return profile_backends(_node.profile, graph=_node.graph, node=patches.caller_id())


def _tag() -> Dict[str, str]:
    """What micros_rt endpoints tell peers about themselves (DDS USER_DATA): the graph and the node."""
    return {"graph": _node.graph, "node": patches.caller_id()}


def _check_subscriber(data_class: Any, callback: Any) -> None:
    _require_node()
    _check_data_class(data_class)
    if not callable(callback):
        raise TypeError(f"callback must be callable, got {callback!r}")


def _check_data_class(data_class: Any) -> None:
    if not (isinstance(data_class, type) and issubclass(data_class, genpy.Message)):
        raise TypeError(f"data_class must be a ROS message class (e.g. std_msgs.msg.String), got {data_class!r}")
