"""The relay's ``ros2:`` section: topics, services and actions between this ROS 1 graph and ROS 2 (the same DDS
domain).

Each entry names a topic, a service or an action; which one is found at run time, and an entry nobody offers yet
is looked for again every poll (:meth:`Ros2Side.poll`). Actions: :mod:`.actions`, on the node API's
``offer_action_to_ros2`` and ``offer_ros2_action``.

- **export** (ROS 1 -> ROS 2). A topic with a publisher in the master (other than this relay): a micros_rt
  subscription over TCPROS (stock publishers), whose callback writes each message on a DDS writer of
  ``rt/<name>`` (``as:`` renames it) with the entry's QoS, behind the core's send queue, as the graph section's
  exports; rclpy reads it as any ROS 2 topic. A latching publisher (its connection header says
  ``latching=1``) makes the writer transient_local, keep_last 1, so late ROS 2 subscribers that ask for
  transient_local get the last message. A service in the master: served to ROS 2 clients by the process's ROS 2
  helper (:mod:`micros_rt.services.gateway`), each request forwarded to the ROS 1 server over TCPROS.
- **import** (ROS 2 -> ROS 1). A topic with DDS writers of ``rt/<name>`` that are not this graph's (ROS 2 nodes;
  micros_rt writers of another graph): a :class:`~micros_rt.transports.dds.feed.DDSFeed` of those writers feeds
  ``NodeHandle.subscribe_reader`` (the core's QoS, queue and statistics), whose callback publishes on a
  micros_rt publication registered with the master, so ``rostopic list/info/echo/hz`` see it. A
  transient_local writer makes the import latched. The publication serves TCPROS only (the relay's profile
  keeps it off DDS: ROS 2 subscribers have the original). A service with a ROS 2 server (a reader of
  ``rq/<name>Request``): a ROS 1 service (``NodeHandle.advertise_service``) whose calls go to that server
  through the helper.

Types come from DDS discovery (``pkg::msg::dds_::Name_`` is ``pkg/Name``) and the master, and are mapped at run
time: nothing is compiled. No loops: a name is carried one way (the configuration refuses the same name both
ways), an import takes no writer of this graph (the relay's own exports included), and an export drops what
this relay published itself.
"""

from __future__ import annotations

import dataclasses
import math
import re
import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, NamedTuple, Optional, Set, Tuple, Type

import genpy
import roslib.message
import rospy

import micros_rt
from micros_rt.extend import SendQueue, latch_several, sender_for
from micros_rt.qos.options import drop_counters
from micros_rt.log import nonblocking_logger
from micros_rt.qos import SubscribeQoSOptions
from micros_rt.transports.base import EndpointSpec, PushReader, TransportWriter

from ...ros2_types import (Ros2TypeError, python_modules_dir, ros2_message_class, ros2_service_class,
                           write_python_modules)
from .config import ExportRule, Ros2Entry
from .msgtypes import TypeLearningError, class_from_definition, installed_class, publisher_header
from .services import ServiceCallError, call_service

__all__ = ["GraphState", "Ros2Directory", "Ros2Side", "ros1_type"]

_log = nonblocking_logger("rosout.micros_rt.relay")

_MSG_TYPE = re.compile(r"^(\w+)::msg::dds_::(\w+)_$")
_SRV_REQUEST_TYPE = re.compile(r"^(\w+)::srv::dds_::(\w+)_Request_$")


def ros1_type(dds_type: str) -> Optional[str]:
    """ROS 2's DDS type name to the ROS 1 type: ``std_msgs::msg::dds_::String_`` -> ``std_msgs/String``; a service
    request's ``std_srvs::srv::dds_::SetBool_Request_`` -> ``std_srvs/SetBool``; None for anything else."""
    found = _MSG_TYPE.match(dds_type) or _SRV_REQUEST_TYPE.match(dds_type)
    return f"{found.group(1)}/{found.group(2)}" if found else None


class GraphState(NamedTuple):
    """The ROS 1 master's view, once per poll."""

    publishers: Dict[str, List[str]]
    subscribers: Dict[str, List[str]]
    services: Dict[str, List[str]]
    types: Dict[str, str]

    @classmethod
    def ask(cls, master: Any) -> "GraphState":
        _code, _msg, (pubs, subs, services) = master.getSystemState()
        _code, _msg, types = master.getTopicTypes()
        return cls({t: list(n) for t, n in pubs}, {t: list(n) for t, n in subs}, {s: list(n) for s, n in services},
                   {t: ty for t, ty in types})

    def type_in_use(self, topic: str, but: FrozenSet[str]) -> Optional[str]:
        """The type ``topic`` has in this graph when a node other than ``but`` publishes or subscribes it."""
        users = [n for n in (*self.publishers.get(topic, ()), *self.subscribers.get(topic, ())) if n not in but]
        found = self.types.get(topic)
        return found if users and found not in (None, "*") else None


class DiscoveredEndpoint(NamedTuple):
    guid: str
    participant: str
    type_name: str
    tag: Optional[Dict[str, str]]      # micros_rt's tag; None: a ROS 2 (or other foreign) endpoint
    transient_local: bool
    best_effort: bool


class Ros2Directory:
    """The DDS writers and readers this participant has discovered, foreign ones included, with their type names
    and QoS: the relay's :class:`~micros_rt.transports.dds.feed.WriterDirectory`'s ``discovery`` (the one reader of
    DDS discovery, :mod:`micros_rt.transports.dds.discovery`)."""

    def __init__(self, tagged: Any) -> None:
        self._discovery = tagged.discovery

    def endpoints(self, kind: str, dds_topic: str) -> List[DiscoveredEndpoint]:
        """Writers (``kind="writers"``) or readers of ``dds_topic`` alive now."""
        writers = kind == "writers"
        found = self._discovery.writers(dds_topic) if writers else self._discovery.readers(dds_topic)
        # readers: only ROS 2 servers' are asked for, never tagged
        return [DiscoveredEndpoint(e.guid, e.participant, e.type_name, e.tag if writers else None, e.transient_local,
                                   e.best_effort) for e in found]


# -- topics ------------------------------------------------------------------------------------------------------

class _TopicOut:
    """A ROS 1 topic written to ROS 2 (``rt/<ros2 name>``)."""

    kind = "topic"

    def __init__(self, side: "Ros2Side", entry: Ros2Entry, data_class: Type[genpy.Message], latch: bool) -> None:
        from micros_rt.transports.dds.types import dds_topic_name

        relay = side.relay
        self.entry = entry
        self.latch = latch
        self.node = relay.node
        self.family = relay.share.family | {relay.node}
        self.dds_topic = dds_topic_name(entry.ros2_name)
        self.rule = ExportRule(entry.name, entry.export_options, entry.max_rate, 1 if latch else entry.queue_size,
                               latch)
        self.min_interval = 0.0 if math.isinf(entry.max_rate) else 1.0 / entry.max_rate
        self.received = self.sent = self.rate_capped = self.looped = self.no_reader = self.on_ros2_already = 0
        self.direct: FrozenSet[str] = frozenset()   # micros_rt publishers of this graph: ROS 2 reads them already
        self._last_sent = -math.inf
        options = self.rule.options
        tag = {"graph": relay.graph_id, "node": relay.node, "relay_ros2": relay.config.graph,
               "type": data_class._type, "md5": data_class._md5sum,
               "best_effort": "1" if options.using_best_effort_protocol else "0", "latch": "1" if latch else "0"}
        self._backend, self._spec = relay.backend, EndpointSpec(entry.ros2_name, data_class, self.rule.queue_size,
                                                                latch, tag)
        # A latched topic keeps each ROS 1 publisher's last message for late subscribers, as ROS 1 does (/tf_static:
        # one static transform broadcaster per node): one transient_local writer per publisher, since a writer
        # keeps only its own last message. Otherwise one writer for the topic.
        self.sender: TransportWriter = self._open()
        self.latched: Dict[str, TransportWriter] = {}
        self._lock = threading.Lock()
        # TCPROS only: a DDS reader of the topic would also hear ROS 2's own publishers of it, and send them back
        self.sub = relay.nh.subscribe(entry.name, data_class, self._on_message, self.rule.queue_size,
                                      micros_rt.TransportHints().tcp())

    def _on_message(self, msg: Any) -> None:
        self.received += 1
        caller = (getattr(msg, "_connection_header", None) or {}).get("callerid")
        if caller in self.family:
            self.looped += 1   # this relay's own import: it never goes back to ROS 2
            return
        if caller in self.direct:
            self.on_ros2_already += 1   # a micros_rt publisher: ROS 2 nodes read its own DDS writer
            return
        now = time.monotonic()
        if now - self._last_sent < self.min_interval:
            self.rate_capped += 1
            return
        with self._lock:  # refresh() may close a departed publisher's writer meanwhile
            sender = self.sender if not self.latch or caller is None else self._latched_sender(caller)
            prepared = sender.prepare(msg)
            if prepared is None:
                self.no_reader += 1  # no ROS 2 subscriber now (a volatile topic keeps nothing for later ones)
                return
            self._last_sent = now
            sender.send(prepared)
            self.sent += 1

    def _open(self) -> TransportWriter:
        options = self.rule.options
        return sender_for(self._backend.open_writer(self._spec, options), topic=self.entry.ros2_name,
                          queue_size=self.rule.queue_size, options=options)

    def _latched_sender(self, caller: str) -> TransportWriter:
        sender = self.latched.get(caller)
        if sender is None:
            in_use = any(x is self.sender for x in self.latched.values())
            sender = self.latched[caller] = self._open() if in_use else self.sender
        return sender

    def refresh(self, side: "Ros2Side", state: GraphState) -> None:
        publishers = set(state.publishers.get(self.entry.name, ()))
        with self._lock:
            for caller in [c for c in self.latched if c not in publishers]:
                # a ROS 1 publisher that went away takes its latched message with it, as in ROS 1
                sender = self.latched.pop(caller)
                sender.close()
                if sender is self.sender:
                    self.sender = self._open()  # the topic's writer again, without that publisher's message
        if self.entry.ros2_name == self.entry.name:
            # micros_rt nodes of this graph are ROS 2 nodes already: their messages are not written twice
            self.direct = frozenset(e.tag.get("node", "") for e in side.directory.endpoints("writers", self.dds_topic)
                                    if e.tag and e.tag.get("graph") == side.relay.graph_id
                                    and "relay_ros2" not in e.tag) - {""}

    def stats(self) -> Dict[str, Any]:
        senders = {id(x): x for x in (self.sender, *self.latched.values())}.values()
        lane_dropped = sum(x.dropped for x in senders if isinstance(x, SendQueue))
        return {"direction": "export", "kind": "topic", "name": self.entry.name, "as": self.entry.ros2_name,
                "latch": self.latch, "latched_publishers": sorted(self.latched),
                "received": self.received, "sent": self.sent, "rate_capped": self.rate_capped,
                "looped": self.looped, "on_ros2_already": self.on_ros2_already, "no_reader": self.no_reader,
                "superseded": lane_dropped, "dropped_queue_full": self.sub.statistics().dropped_queue_full}

    def close(self) -> None:
        self.sub.unregister()
        with self._lock:
            for sender in {id(x): x for x in (self.sender, *self.latched.values())}.values():
                sender.close()
            self.latched.clear()


class _TopicIn:
    """A ROS 2 topic published in this graph."""

    kind = "topic"

    def __init__(self, side: "Ros2Side", entry: Ros2Entry, data_class: Type[genpy.Message], latch: bool,
                 best_effort: bool, type_source: str) -> None:
        from micros_rt.transports.dds.feed import DDSFeed

        relay = side.relay
        self.entry = entry
        self.latch = latch
        self.type_source = type_source   # "installed" (ROS 1's package) or "ROS 2 definition" (built here)
        self.feed: Optional[DDSFeed] = None
        own_graph = relay.graph_id
        # latched: each transient_local writer's last message (several writers' at once, as static transform
        # broadcasters send theirs on discovery), kept for late ROS 1 subscribers as ROS 1 keeps one per publisher
        self.latched: Dict[str, Any] = {}   # writer guid -> its last message, oldest first
        self._lock = threading.Lock()
        queue_size = entry.queue_size
        options = entry.import_options
        if best_effort and not (options and options.using_best_effort_protocol):
            # a reliable reader does not match a best-effort writer: take it as it is sent
            options = dataclasses.replace(options or SubscribeQoSOptions(ordered_by_sending_timestamp=False),
                                          using_best_effort_protocol=True)

        def accept(tag: Optional[Dict[str, str]]) -> bool:
            # ROS 2 nodes (no tag) and other graphs' micros_rt writers; never this graph's (its nodes are in the
            # master already, and this relay's exports must not come back)
            return tag is None or tag.get("graph") != own_graph

        def open_reader(depth: Optional[int], wake: Callable[[], None]) -> PushReader:
            push = PushReader("DDS", depth, wake, blocking=False)
            tag = {"graph": own_graph, "node": relay.node, "relay_ros2_import": relay.config.graph}
            self.feed = DDSFeed(relay.backend, EndpointSpec(entry.ros2_name, data_class, queue_size, latch, tag),
                                options, push, accept)
            return push

        # the relay's QoS profile keeps this publication off DDS (TCPROS only): ROS 2 has the original
        self.pub = relay.nh.advertise(entry.ros1_name, data_class, queue_size, latch=latch)
        if latch:
            latch_several(self.pub, self._lock, lambda: list(self.latched.values()))
        self.sub = relay.nh.subscribe_reader(f"relay ROS 2 import {entry.ros2_name}", data_class, open_reader,
                                             self._publish_latched if latch else self.pub.publish, queue_size,
                                             options)

    def _publish_latched(self, msg: Any) -> None:
        writer = (getattr(msg, "_connection_header", None) or {}).get("writer", "")
        with self._lock:
            self.latched.pop(writer, None)
            self.latched[writer] = msg
            self.pub.publish(msg)

    def refresh(self, side: "Ros2Side", state: GraphState) -> None:
        if not self.latched:
            return
        from micros_rt.transports.dds.types import dds_topic_name

        alive = {w.guid for w in side.directory.endpoints("writers", dds_topic_name(self.entry.ros2_name))}
        with self._lock:
            for writer in [w for w in self.latched if w not in alive]:
                del self.latched[writer]   # a ROS 2 writer gone takes its latched message with it, as in ROS 1

    def stats(self) -> Dict[str, Any]:
        s = self.sub.statistics()
        feed = self.feed
        return {"direction": "import", "kind": "topic", "name": self.entry.name, "as": self.entry.ros1_name,
                "type_source": self.type_source, "latch": self.latch, "latched_writers": len(self.latched), "received": s.received,
                "published": s.delivered,
                "dropped_queue_full": s.dropped_queue_full, **{c: getattr(s, c) for c in drop_counters()},
                "refused": feed.refused if feed else 0, "unknown_writer": feed.unknown_writer if feed else 0,
                "bad_input": feed.bad_input if feed else 0,
                "lost": feed.lost if feed else 0}

    def close(self) -> None:
        self.sub.unregister()
        if self.feed is not None:
            self.feed.close()
        self.pub.unregister()


# -- services ----------------------------------------------------------------------------------------------------

class _ServiceOut:
    """A ROS 1 service offered to ROS 2 clients by the helper; each request goes to the ROS 1 server."""

    kind = "service"

    def __init__(self, side: "Ros2Side", entry: Ros2Entry, service_class: Any, uri: str) -> None:
        from micros_rt.services import srv_mapping

        self.entry = entry
        self.uri = uri
        self.node = side.relay.node
        self.calls = self.failed = 0
        self._class = service_class
        self._mapping = srv_mapping(service_class)
        self._gateway = side.gateway()
        self._gateway.advertise(entry.ros2_name, self._mapping.ros2_type, self._serve)

    def _serve(self, body: bytes) -> bytes:
        self.calls += 1
        try:
            request = self._mapping.decode_request(body)
            response = call_service(self.uri, self.entry.name, self._class, request, caller_id=self.node,
                                    timeout=self.entry.timeout)
            return self._mapping.encode_response(response)
        except Exception as exc:
            self.failed += 1
            # ROS 2 services carry no error: the ROS 2 client sees its own timeout; say why here
            _log.warning("micros_rt: relay: ROS 2 call of %s (ROS 1 server %s) failed, the ROS 2 client gets no "
                         "answer: %s", self.entry.ros2_name, self.uri, exc)
            raise

    def refresh(self, side: "Ros2Side", state: GraphState) -> None:
        pass

    def stats(self) -> Dict[str, Any]:
        return {"direction": "export", "kind": "service", "name": self.entry.name, "as": self.entry.ros2_name,
                "type": self._class._type, "server": self.uri, "calls": self.calls, "failed": self.failed}

    def close(self) -> None:
        self._gateway.unadvertise(self.entry.ros2_name)


class _ServiceIn:
    """A ROS 2 service offered in this graph (``rosservice call`` reaches the ROS 2 server)."""

    kind = "service"

    def __init__(self, side: "Ros2Side", entry: Ros2Entry, service_class: Any) -> None:
        from micros_rt.services import srv_mapping

        self.entry = entry
        self.calls = self.failed = 0
        self._class = service_class
        self._mapping = srv_mapping(service_class)
        self._gateway = side.gateway()
        self._gateway.prepare_client(entry.ros2_name, self._mapping.ros2_type)
        self.server = side.relay.nh.advertise_service(entry.ros1_name, service_class, self._call, ros2=False)

    def _call(self, request: Any) -> Any:
        from micros_rt.services import Ros2Unavailable

        self.calls += 1
        name = self.entry.ros2_name
        try:
            body = self._mapping.encode_request(request)
            try:
                answer = self._gateway.call(name, self._mapping.ros2_type, body, self.entry.timeout)
            except RuntimeError:
                # the helper's own discovery may trail the relay's (a server just found): wait for it, once
                if not self._wait_ready(min(self.entry.timeout, 3.0)):
                    raise
                answer = self._gateway.call(name, self._mapping.ros2_type, body, self.entry.timeout)
            return self._mapping.decode_response(answer)
        except TimeoutError:
            self.failed += 1
            raise rospy.ServiceException(f"{name}: the ROS 2 server did not answer within {self.entry.timeout:g} s "
                                         f"(relay timeout)") from None
        except (RuntimeError, Ros2Unavailable) as exc:
            self.failed += 1
            raise rospy.ServiceException(f"{name} (ROS 2): {exc}") from None
        except Exception as exc:
            self.failed += 1
            raise rospy.ServiceException(f"{name} (ROS 2): {type(exc).__name__}: {exc}") from None

    def _wait_ready(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while True:
            if self._gateway.server_ready(self.entry.ros2_name, self._mapping.ros2_type):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)

    def refresh(self, side: "Ros2Side", state: GraphState) -> None:
        pass

    def stats(self) -> Dict[str, Any]:
        return {"direction": "import", "kind": "service", "name": self.entry.name, "as": self.entry.ros1_name,
                "type": self._class._type, "calls": self.calls, "failed": self.failed}

    def close(self) -> None:
        self.server.shutdown("relay closing")


# -- the section -------------------------------------------------------------------------------------------------

class Ros2Side:
    """Carries a relay's ``ros2:`` entries (see the module's text); :meth:`poll` from the relay's poll loop."""

    def __init__(self, relay: Any, entries: Tuple[Ros2Entry, ...]) -> None:
        self.relay = relay
        self.entries = entries
        self.directory = Ros2Directory(relay._directory)
        self.carried: Dict[str, Any] = {}   # key(entry) -> what carries it
        self._lock = threading.Lock()
        self._gateway: Any = None

    def gateway(self) -> Any:
        """The process's ROS 2 helper (started on first use)."""
        if self._gateway is None:
            from micros_rt.services import ros2_gateway

            self._gateway = ros2_gateway()
        return self._gateway

    @staticmethod
    def key(entry: Ros2Entry) -> str:
        return f"ros2 {entry.direction} {entry.name}"

    def poll(self, state: GraphState, attempt: Callable[[str, Callable[[], Optional[str]]], None]) -> None:
        for entry in self.entries:
            carried = self.carried.get(self.key(entry))
            if carried is None:
                make = self._export if entry.direction == "export" else self._import
                attempt(self.key(entry), lambda: make(entry, state))
            elif entry.direction == "export" and carried.kind == "service":
                attempt(self.key(entry), lambda: self._recheck_service(entry, carried, state))
            else:
                carried.refresh(self, state)

    def _own(self) -> FrozenSet[str]:
        return frozenset(self.relay.share.family) | {str(self.relay.node)}

    def _add(self, entry: Ros2Entry, carried: Any) -> None:
        with self._lock:
            self.carried[self.key(entry)] = carried
        self.relay._refused.pop(self.key(entry), None)   # carried now: no longer in not_carried

    def _topic_options_on_service(self, entry: Ros2Entry, what: str = "a service") -> None:
        if entry.topic_keys:
            _log.warning("micros_rt: relay %s: %s: %s is %s; its options %s apply to topics only and are "
                         "not used", self.relay.config.graph, entry.where, entry.name, what,
                         ", ".join(entry.topic_keys))

    def _ros2_service_class(self, type_name: str) -> Any:
        """The installed ROS 1 service class of ``type_name``, else the one built from the ROS 2 installation of the
        process's helper (which serves the calls, so has the type)."""
        found = _service_class(type_name)
        if found is None:
            pkg, _, name = type_name.partition("/")
            found = ros2_service_class(f"{pkg}/srv/{name}", python=self.gateway().python)
            self._for_stock_tools(type_name)
        return found

    def _for_stock_tools(self, type_name: str) -> None:
        """A type built from ROS 2's definition: its Python modules where stock ROS 1 tools can import them
        (``rostopic echo`` loads a topic's class by its package name)."""
        directory = python_modules_dir()
        try:
            packages = write_python_modules(directory)
        except (OSError, ValueError) as exc:
            _log.warning("micros_rt: relay %s: %s has no ROS 1 package here and was built from its ROS 2 definition; "
                         "its Python modules for stock ROS 1 tools could not be written to %s: %s",
                         self.relay.config.graph, type_name, directory, exc)
            return
        if type_name.partition("/")[0] in packages:
            _log.info("micros_rt: relay %s: %s has no ROS 1 package here: built from its ROS 2 definition; stock ROS "
                      "1 tools (rostopic echo, rosservice call) read it with PYTHONPATH=%s", self.relay.config.graph,
                      type_name, directory)
        else:   # ROS 1 has the package, without this type: modules beside it would hide the installed ones
            _log.warning("micros_rt: relay %s: %s was built from its ROS 2 definition, but ROS 1's package %s is "
                         "installed without it: stock ROS 1 tools cannot load it (the relay carries it all the same)",
                         self.relay.config.graph, type_name, type_name.partition("/")[0])

    # -- ROS 1 -> ROS 2 --------------------------------------------------------------------------------------
    def _export(self, entry: Ros2Entry, state: GraphState) -> Optional[str]:
        own = self._own()
        publishers = [n for n in state.publishers.get(entry.name, ()) if n not in own]
        if publishers:
            return self._export_topic(entry, state.types.get(entry.name, ""), tuple(own))
        servers = [n for n in state.services.get(entry.name, ()) if n not in own]
        if servers:
            return self._export_service(entry)
        action_type = self._ros1_action_server(entry.name, state)
        if action_type is not None:
            return self._export_action(entry, action_type)
        return None  # neither published nor served now: looked for again next round

    def _ros1_action_server(self, name: str, state: GraphState) -> Optional[str]:
        """``pkg/FooAction`` when a node other than the relay serves action ``name`` (publishes ``name/status``,
        and ``name/feedback`` is an ``*ActionFeedback``), else None."""
        own = self._own()
        if not [n for n in state.publishers.get(name + "/status", ()) if n not in own]:
            return None
        feedback = state.types.get(name + "/feedback", "")
        return feedback[: -len("Feedback")] if feedback.endswith("ActionFeedback") else None

    def _action_class(self, entry: Ros2Entry, ros2_type: str) -> Tuple[Any, str]:
        from .actions import action_class

        return action_class(ros2_type, self.gateway().python)

    def _export_action(self, entry: Ros2Entry, ros1_type: str) -> Optional[str]:
        from .actions import ActionOut, check_against_server, ros2_action_type

        what = f"{entry.where}: cannot export action {entry.name} ({ros1_type}) to ROS 2"
        if entry.target != entry.name:
            return f"{what}: an action keeps its name on both sides ('as: {entry.target}' is not supported for actions)"
        ros2_type = ros2_action_type(ros1_type)
        try:
            cls, source = self._action_class(entry, ros2_type)
            if cls._type != ros1_type:
                return f"{what}: the ROS 1 class found is {cls._type}"
            check_against_server(cls, entry.name, rospy.get_master(), self.relay.node, tuple(self._own()))
        except TypeLearningError as exc:
            return f"{what}: {exc}"
        self._topic_options_on_service(entry, "an action")
        try:
            out = ActionOut(self.relay.nh, entry, cls, source)
        except (micros_rt.MicrosRtError, TypeError, ValueError) as exc:
            return f"{what}: {exc}"
        self._add(entry, out)
        _log.info("micros_rt: relay %s: ROS 2 export of action %s (%s, class %s) as %s", self.relay.config.graph,
                  entry.name, ros2_type, source, entry.ros2_name)
        return None

    def _export_topic(self, entry: Ros2Entry, type_name: str, own: Tuple[str, ...]) -> Optional[str]:
        master = rospy.get_master()
        why = ""
        try:
            header = publisher_header(master, entry.name, caller_id=self.relay.node, skip=own)
        except TypeLearningError as exc:
            header = {}
            why = str(exc)
        data_class = installed_class(type_name)
        if data_class is None:
            if not header:
                return (f"{entry.where}: cannot export {entry.name} to ROS 2: its type {type_name} is not installed "
                        f"on this host and was not learnt from a publisher: {why}")
            try:  # not installed here: the definition its publisher sent
                data_class = class_from_definition(header.get("type", ""), header.get("md5sum", ""),
                                                   header.get("message_definition", ""))
            except TypeLearningError as exc:
                return (f"{entry.where}: cannot export {entry.name} to ROS 2: its type {type_name} is not "
                        f"installed on this host and was not learnt from a publisher: {exc}")
        latch = entry.latch if entry.latch is not None else header.get("latching") == "1"
        try:
            out = _TopicOut(self, entry, data_class, latch)
        except micros_rt.MicrosRtError as exc:
            return f"{entry.where}: cannot export {entry.name} to ROS 2: {exc}"
        self._add(entry, out)
        _log.info("micros_rt: relay %s: ROS 2 export of topic %s (%s%s) as %s", self.relay.config.graph, entry.name,
                  data_class._type, ", latched: transient_local" if latch else "", entry.ros2_name)
        return None

    def _service_header(self, entry: Ros2Entry) -> Tuple[str, Dict[str, str]]:
        from .services import probe_service

        uri = str(rospy.get_master().lookupService(entry.name)[2] or "")
        if not uri.startswith("rosrpc://"):
            return "", {}
        return uri, probe_service(uri, entry.name, caller_id=self.relay.node, timeout=5.0)

    def _export_service(self, entry: Ros2Entry) -> Optional[str]:
        try:
            uri, header = self._service_header(entry)
        except ServiceCallError as exc:
            return f"{entry.where}: cannot export service {entry.name} to ROS 2: {exc}"
        if not uri:
            return None
        type_name = header.get("type", "")
        try:
            service_class = self._ros2_service_class(type_name)
        except (Ros2TypeError, ValueError, micros_rt.MicrosRtError) as exc:
            return (f"{entry.where}: cannot export service {entry.name} ({type_name or 'type unknown'}) to ROS 2: "
                    f"its package is not installed on this host, and a ROS 2 client's request must be mapped field "
                    f"by field, from the ROS 2 definition when there is no ROS 1 package: {exc}")
        if header.get("md5sum") and header["md5sum"] != service_class._md5sum:
            return (f"{entry.where}: cannot export service {entry.name}: its server has another definition of "
                    f"{type_name} (md5 {header['md5sum']}, here {service_class._md5sum})")
        self._topic_options_on_service(entry)
        try:
            out = _ServiceOut(self, entry, service_class, uri)
        except micros_rt.MicrosRtError as exc:
            return f"{entry.where}: cannot export service {entry.name} to ROS 2: {exc}"
        self._add(entry, out)
        _log.info("micros_rt: relay %s: ROS 2 export of service %s (%s, served at %s) as %s",
                  self.relay.config.graph, entry.name, type_name, uri, entry.ros2_name)
        return None

    def _recheck_service(self, entry: Ros2Entry, carried: _ServiceOut, state: GraphState) -> Optional[str]:
        """The ROS 1 server moved (new address) or went (withdrawn from ROS 2 until one is back)."""
        servers = [n for n in state.services.get(entry.name, ()) if n not in self._own()]
        uri = ""
        if servers:
            try:
                uri = str(rospy.get_master().lookupService(entry.name)[2] or "")
            except Exception as exc:  # the master away for a moment: keep it as it is
                return f"cannot look up service {entry.name}: {exc}"
        if uri.startswith("rosrpc://"):
            carried.uri = uri
            return None
        with self._lock:
            del self.carried[self.key(entry)]
        carried.close()
        _log.warning("micros_rt: relay %s: service %s has no ROS 1 server now: withdrawn from ROS 2 until one is "
                     "back", self.relay.config.graph, entry.name)
        return None

    # -- ROS 2 -> ROS 1 --------------------------------------------------------------------------------------
    def _import(self, entry: Ros2Entry, state: GraphState) -> Optional[str]:
        from micros_rt.transports.dds.types import dds_topic_name

        own_graph = self.relay.graph_id
        writers = [w for w in self.directory.endpoints("writers", dds_topic_name(entry.ros2_name))
                   if w.tag is None or w.tag.get("graph") != own_graph]
        if writers:
            return self._import_topic(entry, writers, state)
        request_topic = "rq/" + entry.ros2_name.lstrip("/") + "Request"
        servers = [r for r in self.directory.endpoints("readers", request_topic) if r.tag is None]
        if servers:
            return self._import_service(entry, servers[0], state)
        from .actions import send_goal_topic

        action_servers = [r for r in self.directory.endpoints("readers", send_goal_topic(entry.ros2_name))
                          if r.tag is None]
        if action_servers:
            return self._import_action(entry, action_servers[0], state)
        return None  # no ROS 2 publisher or server now: looked for again next round

    def _import_action(self, entry: Ros2Entry, server: DiscoveredEndpoint, state: GraphState) -> Optional[str]:
        from .actions import ActionIn, ros2_action_type_of

        what = f"{entry.where}: cannot import action {entry.name} from ROS 2"
        ros2_type = ros2_action_type_of(server.type_name)
        if ros2_type is None:
            return f"{what}: its goal request type {server.type_name} is not a ROS 2 action's"
        if entry.target != entry.name:
            return f"{what}: an action keeps its name on both sides ('as: {entry.target}' is not supported for actions)"
        others = [n for n in state.publishers.get(entry.name + "/status", ()) if n not in self._own()]
        if others:
            return (f"{what}: {', '.join(others)} serves action {entry.name} in this graph already (a micros_rt "
                    f"process offering it to ROS 2 would make it come back as a second server)")
        try:
            cls, source = self._action_class(entry, ros2_type)
        except TypeLearningError as exc:
            return f"{what}: {exc}"
        if source != "installed":
            self._for_stock_tools(cls._type)
        self._topic_options_on_service(entry, "an action")
        try:
            incoming = ActionIn(self.relay.nh, entry, cls, ros2_type, source)
        except (micros_rt.MicrosRtError, TypeError, ValueError) as exc:
            return f"{what}: {exc}"
        self._add(entry, incoming)
        _log.info("micros_rt: relay %s: ROS 2 import of action %s (%s, class %s) as %s", self.relay.config.graph,
                  entry.name, ros2_type, source, entry.ros1_name)
        return None

    def _import_topic(self, entry: Ros2Entry, writers: List[DiscoveredEndpoint], state: GraphState) -> Optional[str]:
        type_name = ros1_type(writers[0].type_name)
        if type_name is None:
            return (f"{entry.where}: cannot import {entry.name} from ROS 2: its DDS type {writers[0].type_name} is "
                    f"not a ROS 2 message type")
        others = sorted({t for t in (ros1_type(w.type_name) for w in writers) if t} - {type_name})
        if others:
            return (f"{entry.where}: cannot import {entry.name} from ROS 2: its publishers use different types "
                    f"({', '.join([type_name, *others])})")
        data_class = installed_class(type_name)
        type_source = "installed"
        if data_class is None:
            type_source = "ROS 2 definition"
            pkg, _, name = type_name.partition("/")
            try:   # ROS 2 discovery carries no definition: the ROS 2 installation's
                data_class = ros2_message_class(f"{pkg}/msg/{name}")
            except (Ros2TypeError, ValueError) as exc:
                return (f"{entry.where}: cannot import {entry.name} from ROS 2: its type {type_name} has no ROS 1 "
                        f"package on this host and cannot be built from its ROS 2 definition: {exc}")
            self._for_stock_tools(type_name)
        local = state.type_in_use(entry.ros1_name, self._own())
        if local is not None and local != type_name:
            return (f"{entry.where}: cannot import {entry.name} from ROS 2 as {entry.ros1_name}: ROS 2 sends "
                    f"{type_name}, and {entry.ros1_name} is {local} in this graph; give the import another name "
                    f"with 'as:'")
        latch = entry.latch if entry.latch is not None else any(w.transient_local for w in writers)
        best_effort = all(w.best_effort for w in writers)
        try:
            incoming = _TopicIn(self, entry, data_class, latch, best_effort, type_source)
        except micros_rt.MicrosRtError as exc:
            return f"{entry.where}: cannot import {entry.name} from ROS 2: {exc}"
        self._add(entry, incoming)
        _log.info("micros_rt: relay %s: ROS 2 import of topic %s (%s%s) as %s", self.relay.config.graph,
                  entry.name, type_name, ", transient_local: latched" if latch else "", entry.ros1_name)
        return None

    def _import_service(self, entry: Ros2Entry, server: DiscoveredEndpoint, state: GraphState) -> Optional[str]:
        type_name = ros1_type(server.type_name)
        if type_name is None:
            return (f"{entry.where}: cannot import service {entry.name} from ROS 2: its request type "
                    f"{server.type_name} is not a ROS 2 service type")
        others = [n for n in state.services.get(entry.ros1_name, ()) if n not in self._own()]
        if others:
            return (f"{entry.where}: cannot import service {entry.name} from ROS 2 as {entry.ros1_name}: "
                    f"{', '.join(others)} serves {entry.ros1_name} in this graph already")
        try:
            service_class = self._ros2_service_class(type_name)
        except (Ros2TypeError, ValueError, micros_rt.MicrosRtError) as exc:
            return (f"{entry.where}: cannot import service {entry.name} from ROS 2: its type {type_name} has no "
                    f"ROS 1 package on this host and cannot be built from its ROS 2 definition: {exc}")
        from micros_rt.services import srv_mapping

        try:
            ready = self.gateway().server_ready(entry.ros2_name, srv_mapping(service_class).ros2_type)
        except micros_rt.MicrosRtError as exc:
            return f"{entry.where}: cannot import service {entry.name} from ROS 2: {exc}"
        if not ready:
            # The relay's discovery saw the server before its helper's client did (1.7-2.5 s after the helper's
            # start here): offered in ROS 1 only once a call reaches it, else a ROS 1 client that waited for the
            # service has its first call held for up to 3 s, or refused. Looked at again next round.
            return None
        self._topic_options_on_service(entry)
        try:
            incoming = _ServiceIn(self, entry, service_class)
        except micros_rt.MicrosRtError as exc:
            return f"{entry.where}: cannot import service {entry.name} from ROS 2: {exc}"
        self._add(entry, incoming)
        _log.info("micros_rt: relay %s: ROS 2 import of service %s (%s) as %s", self.relay.config.graph, entry.name,
                  type_name, entry.ros1_name)
        return None

    # -- reporting -----------------------------------------------------------------------------------------
    def stats(self) -> List[Dict[str, Any]]:
        with self._lock:
            carried = dict(self.carried)
        out: List[Dict[str, Any]] = []
        for entry in self.entries:
            found = carried.get(self.key(entry))
            if found is not None:
                out.append(found.stats())
            else:
                out.append({"direction": entry.direction, "kind": None, "name": entry.name,
                            "as": entry.target, "state": "not found yet" if entry.direction == "import" else
                            "no ROS 1 publisher, server or action server yet"})
        return out

    def close(self) -> None:
        with self._lock:
            carried = list(self.carried.values())
            self.carried.clear()
        for item in carried:
            try:
                item.close()
            except Exception as exc:  # a master or helper gone at shutdown: nothing is left open here
                _log.debug("micros_rt: relay: closing a ROS 2 entry: %s", exc)


def _service_class(type_name: str) -> Any:
    try:
        return roslib.message.get_service_class(type_name) if "/" in type_name else None
    except (ValueError, ImportError):
        return None
