"""rospy's ``init_node``, ``Publisher`` and ``Subscriber`` on micros_rt, for scripts nobody rewrites.

``micros-rt run SCRIPT`` calls :func:`install` and then runs the script: its ``rospy.init_node`` starts a
micros_rt node (YAML profile, negotiation hooks), its ``rospy.Publisher``/``rospy.Subscriber`` are
micros_rt endpoints behind rospy's signatures, so two scripts run this way talk DDS and each still talks
TCPROS to stock nodes. Its ``rospy.Service`` also serves ROS 2 clients of the same name, and its
``rospy.ServiceProxy`` also reaches a ROS 2 server (:mod:`micros_rt.services`). Everything else (parameters,
timers, time, logging, ``spin``, ``on_shutdown``) is rospy's own, untouched; ``rospy.wait_for_service`` waits for a
ROS 1 server in the master or a ROS 2 server of the name. actionlib's ``ActionClient.wait_for_server`` (also
``SimpleActionClient``'s) waits the same way, and for an action only a ROS 2 server has it makes
:meth:`micros_rt.NodeHandle.offer_ros2_action` of it in this process (:func:`wait_for_action_server`).

The drop-in classes subclass rospy's own classes, so ``isinstance(pub, rospy.Publisher)`` holds both for
the patched name and for rospy's original class. What stays on stock rospy (TCPROS only):
``rospy.AnyMsg`` endpoints (no type to map to DDS) and endpoints made before ``init_node`` (rospy allows
that; micros_rt needs the node first).

>>> from micros_rt import drop_in
>>> drop_in.install(profile="qos.yaml")           # doctest: +SKIP
>>> import rospy; rospy.init_node("talker")         # a micros_rt node now  # doctest: +SKIP
"""

from __future__ import annotations

import sys
import threading
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Set, Type

import genpy
import rospy
import rospy.client
import rospy.names
import rospy.topics

from .transports.tcpros import patches
from .transports.links import links_of
from . import node as _node
from .log import nonblocking_logger
from .negotiation.hints import TransportHints

__all__ = ["Publisher", "Service", "ServiceProxy", "Subscriber", "init_node", "install", "wait_for_action_server",
           "wait_for_message", "wait_for_service"]

_log = nonblocking_logger("rosout.micros_rt")
_ROSPY_INIT_NODE: Callable[..., Any] = rospy.init_node
_DEFAULT_BUFF_SIZE: int = int(getattr(rospy.topics, "DEFAULT_BUFF_SIZE", 65536))


@dataclass
class _Settings:
    profile: Optional[str] = None
    hints: TransportHints = field(default_factory=TransportHints)
    initialized: bool = False  # init_node went through micros_rt
    starting: bool = False  # inside micros_rt.init_node, which calls rospy.init_node: the real one
    early: List[str] = field(default_factory=list)  # topics of endpoints made before init_node (stock)


_settings = _Settings()


def install(*, profile: Optional[str] = None, hints: Optional[TransportHints] = None) -> None:
    """Put micros_rt under rospy's names: ``rospy.init_node``, ``rospy.Publisher``, ``rospy.Subscriber``,
    ``rospy.Service``, ``rospy.ServiceProxy``, ``rospy.wait_for_service`` and ``rospy.wait_for_message``; and
    actionlib's ``ActionClient.wait_for_server`` (:func:`wait_for_action_server`) when actionlib is installed.
    Idempotent.

    ``rospy.topics.Publisher``/``Subscriber`` stay rospy's: rospy's own methods name them through
    their module (``super(Subscriber, self)``), so replacing them there would break every rospy endpoint.

    ``profile``: a YAML QoS profile (else ``MICROS_RT_QOS_PROFILE``, as for ``micros_rt.init_node``);
    ``hints``: every subscription's protocol order (default shared memory on one host, DDS, then TCPROS).
    """
    _settings.profile = profile
    _settings.hints = hints or TransportHints()
    rospy.names.reload_mappings(sys.argv)  # the script's remapping arguments
    rospy.init_node = init_node
    rospy.Publisher = Publisher
    rospy.Subscriber = Subscriber
    rospy.Service = Service
    rospy.ServiceProxy = ServiceProxy
    rospy.wait_for_service = wait_for_service
    rospy.wait_for_message = rospy.client.wait_for_message = wait_for_message
    _install_actionlib()


def init_node(name: str, argv: Optional[List[str]] = None, anonymous: bool = False, **kwargs: Any) -> None:
    """``rospy.init_node`` with micros_rt underneath (same arguments, same errors)."""
    if _settings.starting or _settings.initialized:
        # micros_rt's own call, or a second call (rospy accepts the same arguments, refuses others)
        _ROSPY_INIT_NODE(name, argv=argv, anonymous=anonymous, **kwargs)
        return
    _settings.starting = True
    # before micros_rt's own hook, which closes the topics: the offers' actionlib servers stop publishing first
    rospy.on_shutdown(_close_ros2_actions)
    try:
        _node.init_node(name, argv, anonymous, qos_profile=_settings.profile, **kwargs)
    finally:
        _settings.starting = False
    _settings.initialized = True
    if _settings.early:
        _log.warning("micros_rt: the publishers/subscribers of %s were made before rospy.init_node and stay on "
                     "stock rospy (TCPROS only); make them after init_node to use DDS",
                     ", ".join(sorted(set(_settings.early))))


init_node.__doc__ = (init_node.__doc__ or "") + "\n" + (getattr(_ROSPY_INIT_NODE, "__doc__", "") or "")


def _on_micros_rt(name: Any, data_class: Any) -> bool:
    """Whether an endpoint of ``data_class`` made now can be micros_rt's (otherwise stock rospy's)."""
    if not _settings.initialized:
        if not _settings.starting:  # rospy's own /clock subscriber in init_node needs no word
            _settings.early.append(str(name))
        return False
    return getattr(data_class, "_md5sum", "*") != "*"


def _take_names(obj: Any, endpoint: Any, reg_type: str) -> None:
    # the attributes rospy's Topic sets, so code reading them sees what a rospy endpoint shows
    obj.resolved_name = obj.name = endpoint.resolved_name
    obj.data_class = endpoint.data_class
    obj.type = endpoint.type
    obj.md5sum = endpoint.md5sum
    obj.reg_type = reg_type
    obj.impl = patches.topic_impl(endpoint.resolved_name, publisher=reg_type == "pub")


class Publisher(patches.ROSPY_PUBLISHER):  # type: ignore[misc]
    """``rospy.Publisher`` on micros_rt: DDS to micros_rt subscribers, TCPROS to the others.

    Same arguments and behaviour as rospy's: ``queue_size`` (None: synchronous, nothing lost),
    ``latch``, ``tcp_nodelay`` and ``headers`` (TCPROS links), ``subscriber_listener`` (told about TCPROS
    and DDS subscribers; for a DDS subscriber ``peer_publish`` reaches every DDS subscriber of the topic,
    as DDS cannot address one reader). ``micros_rt`` is the underlying :class:`micros_rt.Publisher`
    (``statistics()``, ``qos``), None when the publisher is stock rospy's.
    """

    def __init__(self, name: str, data_class: Type[genpy.Message], subscriber_listener: Any = None,
                 tcp_nodelay: bool = False, latch: bool = False, headers: Optional[Dict[str, str]] = None,
                 queue_size: Optional[int] = None) -> None:
        self.micros_rt: Optional[_node.Publisher] = None
        self._listener: Optional[_Listener] = None
        if not _on_micros_rt(name, data_class):
            super().__init__(name, data_class, subscriber_listener=subscriber_listener, tcp_nodelay=tcp_nodelay,
                             latch=latch, headers=headers, queue_size=queue_size)
            return
        if queue_size is None:
            warnings.warn("The publisher should be created with an explicit keyword argument 'queue_size'. "
                          "Please see http://wiki.ros.org/rospy/Overview/Publishers%20and%20Subscribers for more "
                          "information.", SyntaxWarning, stacklevel=2)
        pub = _node.NodeHandle().advertise(name, data_class, queue_size, latch=latch)
        self.micros_rt = pub
        _take_names(self, pub, "pub")
        if tcp_nodelay:
            patches.set_publisher_tcp_nodelay(pub.resolved_name)
        if subscriber_listener is not None and self.impl is not None:
            self._listener = _Listener(subscriber_listener, self.publish)
            _dds_subscribers.watch(pub.resolved_name, self._listener)
        patches.configure_publisher_impl(self.impl, headers=headers, subscriber_listener=self._listener)

    def publish(self, *args: Any, **kwds: Any) -> None:
        pub = self.micros_rt
        if pub is None:
            super().publish(*args, **kwds)
        else:
            pub.publish(*args, **kwds)

    def get_num_connections(self) -> int:
        pub = self.micros_rt
        return int(super().get_num_connections()) if pub is None else pub.get_num_connections()

    def unregister(self) -> None:
        pub, self.micros_rt = self.micros_rt, None
        if pub is None:
            super().unregister()
            return
        if self._listener is not None:
            _dds_subscribers.forget(pub.resolved_name, self._listener)
        self.impl = None
        pub.unregister()


class Subscriber(patches.ROSPY_SUBSCRIBER):  # type: ignore[misc]
    """``rospy.Subscriber`` on micros_rt: DDS from micros_rt publishers, TCPROS from the others.

    Same arguments and behaviour as rospy's: ``callback(msg)`` or ``callback(msg, callback_args)``,
    ``queue_size`` (None: nothing dropped), ``buff_size`` and ``tcp_nodelay`` (TCPROS links).
    ``msg._connection_header["transport"]`` says ``DDS`` for DDS messages. ``micros_rt`` is the underlying
    :class:`micros_rt.Subscriber` (``statistics()``, ``latency``, ``connection_transports()``).
    """

    def __init__(self, name: str, data_class: Type[genpy.Message], callback: Optional[Callable[..., Any]] = None,
                 callback_args: Any = None, queue_size: Optional[int] = None, buff_size: int = _DEFAULT_BUFF_SIZE,
                 tcp_nodelay: bool = False) -> None:
        self.micros_rt: Optional[_node.Subscriber] = None
        if not _on_micros_rt(name, data_class):
            super().__init__(name, data_class, callback=callback, callback_args=callback_args,
                             queue_size=queue_size, buff_size=buff_size, tcp_nodelay=tcp_nodelay)
            return
        sub = _node.NodeHandle().subscribe(name, data_class, callback if callback is not None else _ignore,
                                           queue_size, _settings.hints, callback_args=callback_args)
        self.micros_rt = sub
        _take_names(self, sub, "sub")
        self.callback, self.callback_args = callback, callback_args
        patches.configure_subscriber_impl(self.impl, buff_size=None if buff_size == _DEFAULT_BUFF_SIZE else buff_size,
                                         tcp_nodelay=tcp_nodelay)

    def get_num_connections(self) -> int:
        sub = self.micros_rt
        return int(super().get_num_connections()) if sub is None else sub.get_num_connections()

    def unregister(self) -> None:
        sub, self.micros_rt = self.micros_rt, None
        if sub is None:
            super().unregister()
            return
        self.impl = None
        self.callback = self.callback_args = None
        sub.unregister()


class Service(patches.ROSPY_SERVICE):  # type: ignore[misc]
    """``rospy.Service`` on micros_rt: rospy's own for ROS 1 clients (same arguments, same behaviour), and the
    handler also answers ROS 2 clients (rclpy) of the same name. ``micros_rt`` is the ROS 2 side
    (:class:`micros_rt.services.ServiceServer`: ``serves_ros2``, ``ros2_error``), None before ``init_node`` or
    when the type does not map to ROS 2 (said once, in words)."""

    def __init__(self, name: str, service_class: Any, handler: Callable[[Any], Any], *args: Any,
                 **kwargs: Any) -> None:
        super().__init__(name, service_class, handler, *args, **kwargs)
        self.micros_rt: Any = None
        if _settings.initialized:
            from .services import advertise_service

            self.micros_rt = advertise_service(self.resolved_name, service_class, handler, ros1=False)

    def shutdown(self, reason: str = "") -> None:
        server, self.micros_rt = self.micros_rt, None
        if server is not None:
            server.shutdown(reason)
        super().shutdown(reason)


class ServiceProxy(patches.ROSPY_SERVICE_PROXY):  # type: ignore[misc]
    """``rospy.ServiceProxy`` on micros_rt: a call goes to the ROS 1 server registered with the master, else to a
    ROS 2 server of the same name (:class:`micros_rt.services.ServiceClient`); ``wait_for_service`` waits for
    either. Errors are rospy's exceptions (``rospy.ServiceException``, ``rospy.ROSException``) with words. A
    ``persistent`` proxy or one with ``headers`` (ROS 1 notions) stays rospy's own, ROS 1 only."""

    def __init__(self, name: str, service_class: Any, persistent: bool = False,
                 headers: Optional[Dict[str, str]] = None) -> None:
        super().__init__(name, service_class, persistent=persistent, headers=headers)
        self.micros_rt: Any = None
        if _settings.initialized and not persistent and not headers:
            from .services import service_client

            self.micros_rt = service_client(self.resolved_name, service_class)

    def wait_for_service(self, timeout: Optional[float] = None) -> None:
        client = self.micros_rt
        if client is None:
            super().wait_for_service(timeout)
        else:
            client.wait_for_service(timeout)

    def call(self, *args: Any, **kwds: Any) -> Any:
        client = self.micros_rt
        return super().call(*args, **kwds) if client is None else client.call(*args, **kwds)

    def close(self) -> None:
        client, self.micros_rt = self.micros_rt, None
        if client is not None:
            client.close()
        super().close()


_ROSPY_WAIT_FOR_SERVICE: Callable[..., Any] = rospy.wait_for_service


def wait_for_service(service: str, timeout: Optional[float] = None) -> None:
    """``rospy.wait_for_service``: until a ROS 1 server of ``service`` is in the master, or a ROS 2 server of that
    name is discovered; ``rospy.ROSException`` after ``timeout`` seconds, as rospy raises."""
    if not _settings.initialized:
        _ROSPY_WAIT_FOR_SERVICE(service, timeout)
        return
    from .services import ServiceTimeoutError, ros2_gateway
    from .services.gateway import Ros2Unavailable, ros2_present

    resolved = rospy.names.resolve_name(service)
    deadline = None if timeout is None else time.monotonic() + timeout
    ros2_note = ""
    while True:
        try:
            _ROSPY_WAIT_FOR_SERVICE(resolved, 0.2)  # rospy's own master lookup, 0.2 s at a time
            return
        except rospy.ROSException:
            pass
        try:
            if ros2_present() and resolved in ros2_gateway().server_names():
                return
        except Ros2Unavailable as exc:
            ros2_note = f" (ROS 2 unreachable: {exc})"
        if rospy.is_shutdown():
            raise rospy.ROSInterruptException(f"the node shut down while waiting for service {resolved}")
        if deadline is not None and time.monotonic() >= deadline:
            raise ServiceTimeoutError(f"timeout exceeded while waiting for service {resolved} ({timeout:g} s): no "
                                      f"ROS 1 server registered with the master, no ROS 2 server discovered{ros2_note}")


_ACTIONLIB_WAIT_FOR_SERVER: Optional[Callable[..., Any]] = None  # actionlib's own ActionClient.wait_for_server
_ros2_actions: Dict[str, Any] = {}  # action name -> the ActionFromRos2 this process offers its clients
_ros2_actions_said: Set[str] = set()  # names whose ROS 2 failure was logged
_ros2_actions_lock = threading.Lock()


def _install_actionlib() -> None:
    """Put :func:`wait_for_action_server` in actionlib's ``ActionClient`` (the class: ``SimpleActionClient`` and
    ``wait_for_action_server_to_start`` call it through ``self``); nothing when actionlib is not installed."""
    global _ACTIONLIB_WAIT_FOR_SERVER
    try:
        from actionlib.action_client import ActionClient  # type: ignore[import-untyped]
    except ImportError:
        return
    if ActionClient.wait_for_server is not wait_for_action_server:
        _ACTIONLIB_WAIT_FOR_SERVER = ActionClient.wait_for_server
        ActionClient.wait_for_server = wait_for_action_server


def wait_for_action_server(self: Any, timeout: Any = None) -> bool:
    """actionlib's ``ActionClient.wait_for_server(timeout)`` (``self`` the ActionClient, ``timeout`` a
    ``rospy.Duration``, 0 for ever): True once a server is connected, False after ``timeout``, as actionlib's.

    While no ROS 1 server of the action is in the master (no publisher of ``NAME/status``) and a ROS 2 action
    server of the name is discovered (its ``NAME/_action/send_goal`` service), this process offers that ROS 2
    server to its actionlib clients with :meth:`micros_rt.NodeHandle.offer_ros2_action` (once per name), and the
    wait ends when actionlib's client is connected to that offer and the offer's helper has discovered the ROS 2
    server. A ROS 1 server is preferred, as ``wait_for_service`` prefers one."""
    original = _ACTIONLIB_WAIT_FOR_SERVER
    assert original is not None
    if timeout is None:
        timeout = rospy.Duration(0.0)
    if not _settings.initialized:
        return bool(original(self, timeout))
    name = str(self.pub_goal.resolved_name).removesuffix("/goal")  # the name actionlib resolved
    forever = timeout == rospy.Duration(0.0)
    deadline = rospy.get_rostime() + timeout
    offer: Any = None
    ros2 = True
    while not rospy.is_shutdown():
        connected = original(self, rospy.Duration(0.2))  # actionlib's own check, 0.2 s at a time
        if connected and (offer is None or offer.ros2_server_ready()):
            return True
        if offer is None and ros2:
            try:
                offer = _ros2_action(name, self.ActionSpec)
            except Exception as exc:  # ROS 2 unreachable, its type missing: actionlib's own wait goes on
                ros2 = False
                if name not in _ros2_actions_said:
                    _ros2_actions_said.add(name)
                    _log.warning("micros_rt: action %s: waiting for a ROS 1 server only: %s", name, exc)
        if not forever and rospy.get_rostime() >= deadline:
            return False
        if connected:
            time.sleep(0.05)
    return False


def _ros2_action(name: str, action_class: Any) -> Any:
    """This process's offer of the ROS 2 action server of ``name``, made now if no ROS 1 server of ``name`` is in
    the master and a ROS 2 one is discovered; else None."""
    with _ros2_actions_lock:
        if name in _ros2_actions:
            return _ros2_actions[name]
        if any(topic == f"{name}/status" for topic, _type in rospy.get_published_topics()):
            return None  # a ROS 1 server (or another process's offer): actionlib's own wait connects to it
        from .services import ros2_gateway
        from .services.gateway import ros2_present

        if not ros2_present() or f"{name}/_action/send_goal" not in ros2_gateway().server_names():
            return None  # no ROS 2 node on the domain (no helper started for nothing), or no such server
        offer = _ros2_actions[name] = _node.NodeHandle().offer_ros2_action(name, action_class)
        _log.info("micros_rt: action %s: served by ROS 2, offered to this process's actionlib clients (%s)", name,
                  offer.ros2_type)
        return offer


def _close_ros2_actions() -> None:
    with _ros2_actions_lock:
        offers = list(_ros2_actions.values())
        _ros2_actions.clear()
    for offer in offers:
        offer.shutdown()


def wait_for_message(topic: str, topic_type: Type[genpy.Message], timeout: Optional[float] = None) -> Any:
    """``rospy.wait_for_message`` through the drop-in :class:`Subscriber` (rospy's builds its own class's
    subscriber, which would see only TCPROS publishers). Same arguments, result and exceptions."""
    got: List[Any] = []
    sub = Subscriber(topic, topic_type, lambda msg: got.append(msg) if not got else None)
    try:
        deadline = None if timeout is None else time.monotonic() + timeout
        while not rospy.is_shutdown() and not got:
            time.sleep(0.01)
            if deadline is not None and time.monotonic() >= deadline:
                raise rospy.ROSException(f"timeout exceeded while waiting for message on topic {topic}")
    finally:
        sub.unregister()
    if rospy.is_shutdown():
        raise rospy.ROSInterruptException("rospy shutdown")
    return got[0]


def _ignore(_msg: Any, *_args: Any) -> None:
    """The callback of a Subscriber made without one (rospy allows that)."""


class _Listener:
    """A user's ``rospy.SubscribeListener`` whose ``topic_publish`` is micros_rt's publish (rospy would
    hand it the TCPROS-only publish of its own topic implementation)."""

    def __init__(self, listener: Any, publish: Callable[..., None]) -> None:
        self.listener = listener
        self.publish = publish

    def peer_subscribe(self, topic_name: str, topic_publish: Any, peer_publish: Callable[..., None]) -> None:
        self.listener.peer_subscribe(topic_name, self.publish, peer_publish)

    def peer_unsubscribe(self, topic_name: str, num_peers: int) -> None:
        self.listener.peer_unsubscribe(topic_name, num_peers)


class _DDSSubscriberWatch:
    """Calls ``peer_subscribe`` for DDS subscribers once DDS discovery matched them (rospy sees only its
    TCPROS connections; a DDS link is ready when its reader is matched, found by the publication's
    housekeeping within about 0.5 s). ``peer_unsubscribe`` needs nothing: removing a DDS link goes
    through rospy's ``remove_connection``, which tells the listeners. One thread, only when needed."""

    PERIOD = 0.1

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._topics: Dict[str, List[_Listener]] = {}
        self._told: Dict[int, Set[int]] = {}  # id(listener) -> DDS connection ids it was told about
        self._thread: Optional[threading.Thread] = None

    def watch(self, topic: str, listener: _Listener) -> None:
        with self._lock:
            self._topics.setdefault(topic, []).append(listener)
            self._told[id(listener)] = set()
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="micros_rt subscriber listeners",
                                                daemon=True)
                self._thread.start()

    def forget(self, topic: str, listener: _Listener) -> None:
        with self._lock:
            listeners = self._topics.get(topic, [])
            if listener in listeners:
                listeners.remove(listener)
            if not listeners:
                self._topics.pop(topic, None)
            self._told.pop(id(listener), None)

    def _run(self) -> None:
        while not rospy.is_shutdown():
            with self._lock:
                if not self._topics:
                    self._thread = None
                    return
                work = [(t, list(ls)) for t, ls in self._topics.items()]
            for topic, listeners in work:
                conns = links_of(topic, publisher=True)
                for listener in listeners:
                    told = self._told.get(id(listener))
                    if told is None:
                        continue
                    for conn in conns:
                        if conn.ready() and conn.id not in told:
                            told.add(conn.id)
                            try:
                                listener.peer_subscribe(topic, listener.publish, listener.publish)
                            except Exception:  # as rospy: a broken listener must not stop the others
                                _log.exception("micros_rt: topic %s: subscriber_listener.peer_subscribe "
                                                     "raised", topic)
                    told &= {c.id for c in conns}
            time.sleep(self.PERIOD)


_dds_subscribers = _DDSSubscriberWatch()
