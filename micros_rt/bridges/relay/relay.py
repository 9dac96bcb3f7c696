"""The relay node: named topics of this ROS graph out to other graphs over DDS, and theirs in.

A thin program on micros_rt's public API (:mod:`micros_rt`, and :mod:`micros_rt.extend` for the process's
DDS back end, the send queue and the node's info section) and the DDS transport:

- **export**: a micros_rt subscription of the local topic (TCPROS from stock roscpp/rospy publishers, DDS
  from micros_rt ones) whose callback sends each message on a DDS writer of ``/<graph><topic>`` with the
  rule's QoS, behind the core's send queue (:class:`~micros_rt.extend.SendQueue`: a KEEP_LAST sample superseded
  before it left is not sent, back-pressure never holds the callback). ``max_rate`` is applied before the
  send queue. The writer's micros_rt tag says ``relay=<graph>``, the ROS type and the QoS: ordinary micros_rt
  readers of other graphs ignore it (they deliver only negotiated writers, or those an importing relay
  names), ROS 2 nodes read it as any topic, and importing relays learn the type from it.
- **import**: a :class:`~micros_rt.transports.dds.feed.DDSFeed` that keeps only samples of the exporting
  graph's relay feeds ``NodeHandle.subscribe_reader`` (the core's deadline, time filter, queue rule and
  statistics), whose callback publishes on a micros_rt publication of the local name: TCPROS to stock
  subscribers; micros_rt subscribers are answered with the exporter's own DDS writer
  (``Publisher.delegate_dds``) and read it straight, with no hop through this process, unless its QoS cannot
  serve them (then this publication's DDS writer does).

- **ros2**: the ``ros2:`` section's topics and services between this graph and ROS 2 nodes of the DDS domain
  (:mod:`.ros2`), set up by the same poll loop, carried by the first process.

Loops: an import never takes its own graph's exports (``relay=`` must name the import's origin graph, and
the configuration refuses ``/<own graph>/...``), and an export drops messages this relay published itself
(an import re-exported under another name would otherwise go round), counted as ``looped``.

Exports are set up when the topic appears on the master (checked every ``poll_period`` s; globs match
topics that come later), imports when an exporting relay's writer has been discovered (its tag names the
type). The message classes come from the installed message packages or, for a type whose package is not
installed, from its definition (:mod:`.msgtypes`: a local publisher's connection header on export, the
exporter's tag on import).
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, Optional, Tuple, Type

import genpy
import roslib.message
import rospy

import micros_rt
from micros_rt.extend import SendQueue, dds_backend, register_info_section, sender_for, unregister_info_section
from micros_rt.qos import DURATION_MAX, SubscribeQoSOptions
from micros_rt.log import nonblocking_logger
from micros_rt.ratelimit import RateLimitedLog
from micros_rt.qos.options import drop_counters
from micros_rt.qos.topic_rules import best_match
from micros_rt.transports.base import EndpointSpec, PushReader, TransportWriter

from .config import ExportRule, ImportRule, RelayConfig, ServiceImport
from .msgtypes import (TypeLearningError, class_from_definition, definition_field, installed_class, learn_from_publisher,
                       raw_service_class)
from .ros2 import GraphState, Ros2Side
from .services import ANNOUNCE_TOPIC, ServiceCallError, call_service, probe_service

__all__ = ["Relay", "Share"]

_log = nonblocking_logger("rosout.micros_rt.relay")


@dataclasses.dataclass(frozen=True)
class Share:
    """The part of a configuration one relay process carries (``micros-rt relay`` runs one process per transport
    priority of its exports, see :mod:`.__main__`; one process carries everything by default)."""

    exports: Optional[FrozenSet[int]] = None   # transport priorities exported here; None: all
    imports: bool = True                       # imports and services
    family: FrozenSet[str] = frozenset()       # node names of the relay's other processes: what they publish
                                               # (imports) never goes back out
    children: Tuple[str, ...] = ()             # the first process: node names of its child processes
    parent: Optional[str] = None               # a child: the first process's node name


class _Export:
    """One local topic going out as ``/<graph><topic>``."""

    def __init__(self, relay: "Relay", rule: ExportRule, topic: str, data_class: Type[genpy.Message]) -> None:
        self.topic = topic
        self.outside = relay.config.outside_name(topic)
        self.rule = rule
        self.node = relay.node
        self.family = relay.share.family
        self.min_interval = 0.0 if math.isinf(rule.max_rate) else 1.0 / rule.max_rate
        self.received = self.sent = self.rate_capped = self.looped = self.no_reader = 0
        self._last_sent = -math.inf
        tag = {"graph": relay.graph_id, "node": relay.node, "relay": relay.config.graph, "type": data_class._type,
               "md5": data_class._md5sum, "best_effort": "1" if rule.options.using_best_effort_protocol else "0",
               "latch": "1" if rule.latch else "0",
               # an importing relay answers micros_rt subscribers with this writer, whose QoS it judges by this
               "qos": json.dumps(rule.options.to_dict(), separators=(",", ":")),
               "def": definition_field(data_class)}  # importers without the type's package build it from this
        spec = EndpointSpec(self.outside, data_class, rule.queue_size, rule.latch, tag)
        writer = relay.backend.open_writer(spec, rule.options)
        # the publication's own rule: the newest queue_size kept, nothing older than the rule's lifespan sent
        self.sender: TransportWriter = sender_for(writer, topic=self.outside, queue_size=rule.queue_size,
                                                  options=rule.options)
        self.sub = relay.nh.subscribe(topic, data_class, self._on_message, rule.queue_size)

    def _on_message(self, msg: Any) -> None:
        self.received += 1
        header = getattr(msg, "_connection_header", None) or {}
        if header.get("callerid") == self.node or header.get("callerid") in self.family:
            self.looped += 1   # this relay's own import of another graph's topic: it never goes back out
            return
        now = time.monotonic()
        if now - self._last_sent < self.min_interval:
            self.rate_capped += 1
            return
        prepared = self.sender.prepare(msg)
        if prepared is None:
            self.no_reader += 1  # no relay or ROS 2 node reads it now
            return
        self._last_sent = now
        self.sender.send(prepared)
        self.sent += 1

    def stats(self) -> Dict[str, Any]:
        superseded = self.sender.dropped if isinstance(self.sender, SendQueue) else 0
        return {"topic": self.topic, "as": self.outside, "received": self.received, "sent": self.sent,
                "rate_capped": self.rate_capped, "looped": self.looped, "no_reader": self.no_reader,
                "superseded": superseded, "dropped_queue_full": self.sub.statistics().dropped_queue_full}

    def info(self) -> Dict[str, Any]:
        """This export in the node's ``microsRtInfo`` (section ``relay``), for the ``micros-rt`` tools."""
        return {"topic": self.topic, "outside": self.outside, "protocol": "DDS", "process": self.node,
                "qos": self.rule.options.to_dict(),
                "max_rate": None if math.isinf(self.rule.max_rate) else self.rule.max_rate,
                "queue_size": self.rule.queue_size, "latch": self.rule.latch, "counters": self.stats()}

    def close(self) -> None:
        self.sub.unregister()
        self.sender.close()


class _Import:
    """One other graph's export, published here as ``rule.local``."""

    def __init__(self, relay: "Relay", rule: ImportRule, data_class: Type[genpy.Message]) -> None:
        from micros_rt.transports.dds.feed import DDSFeed

        self.rule = rule
        self.feed: Optional[DDSFeed] = None
        own_graph = relay.graph_id

        refusals = RateLimitedLog(_log, interval=30.0)

        def accept(tag: Optional[Dict[str, str]]) -> bool:
            if tag is not None and tag.get("relay") == rule.origin and tag.get("graph") != own_graph:
                return True
            if tag is None or tag.get("graph") != own_graph:  # this graph's own writers are refused as a rule
                who = "no micros_rt tag" if tag is None else (f"relay {tag.get('relay')!r} of graph "
                                                              f"{tag.get('graph')!r}, node {tag.get('node')!r}")
                refusals.warning(who, f"micros_rt relay: import {rule.outside}: refusing samples of a DDS writer with "
                                 f"{who} (this import takes relay {rule.origin!r}'s writers only); counted as refused")
            return False

        def open_reader(depth: Optional[int], wake: Callable[[], None]) -> PushReader:
            push = PushReader("DDS", depth, wake, blocking=False)
            tag = {"graph": own_graph, "node": relay.node, "relay_import": relay.config.graph}
            spec = EndpointSpec(rule.outside, data_class, rule.queue_size, rule.latch, tag)
            self.feed = DDSFeed(relay.backend, spec, rule.options, push, accept)
            return push

        self._relay = relay
        self._silent_since: Optional[float] = None  # a deadline missed, nothing since
        options = rule.options
        if options is not None and options.deadline < DURATION_MAX:
            options = dataclasses.replace(options, deadline_cb=self._on_deadline)
        self.pub = relay.nh.advertise(rule.local, data_class, rule.queue_size, latch=rule.latch)
        # the exporter's writers reach this DDS domain already: micros_rt subscribers read them straight, not
        # through this process (on the outside name's DDS topic, with a reader of their own when renamed)
        self.pub.delegate_dds(self._exporter, relay._directory.reader_alive)
        self.sub = relay.nh.subscribe_reader(f"relay import {rule.outside}", data_class, open_reader,
                                             self._deliver, rule.queue_size, options)

    def _exporter(self) -> Optional[micros_rt.ForeignWriters]:
        """A writer of the origin graph's relay for this topic now, with the QoS it offers (its tag)."""
        from micros_rt.transports.dds.types import dds_topic_name

        dds_topic = dds_topic_name(self.rule.outside)
        for writer in self._relay._directory.writers(dds_topic):
            tag = writer.tag
            if tag.get("relay") != self.rule.origin or tag.get("graph") == self._relay.graph_id or "qos" not in tag:
                continue
            try:
                options = micros_rt.AdvertiseQoSOptions.from_dict(json.loads(tag["qos"]),
                                                                 source=f"graph {self.rule.origin}'s relay")
            except (ValueError, TypeError, micros_rt.MicrosRtError) as exc:
                _log.debug("micros_rt: relay: writer %s of %s: unreadable QoS in its tag (%s)", writer.guid,
                           dds_topic, exc)
                continue
            return micros_rt.ForeignWriters(via=self.rule.origin, writer=writer.guid, participant=writer.participant,
                                            topic=self.rule.outside, options=options, latch=tag.get("latch") == "1")
        return None

    def _on_deadline(self, info: micros_rt.DeadlineMissed) -> None:
        if self._silent_since is None:
            self._silent_since = time.monotonic() - info.silent_for
        self._relay.event("deadline", topic=self.rule.outside, silent_for=round(info.silent_for, 3),
                          total=info.total_count)

    def _deliver(self, msg: Any) -> None:
        if self._silent_since is not None:
            silent = time.monotonic() - self._silent_since
            self._silent_since = None
            _log.warning("micros_rt: relay %s: %s from graph %s is back after %.1f s of silence",
                         self._relay.config.graph, self.rule.outside, self.rule.origin, silent)
            self._relay.event("recovered", topic=self.rule.outside, silent_for=round(silent, 3))
        self.pub.publish(msg)

    def stats(self) -> Dict[str, Any]:
        s = self.sub.statistics()
        # the enforcers' counters (expired, filtered, out of order, deadline missed) from the QoS catalogue
        return {"topic": self.rule.outside, "as": self.rule.local, "received": s.received, "published": s.delivered,
                "dropped_queue_full": s.dropped_queue_full, **{c: getattr(s, c) for c in drop_counters()},
                "refused": self.feed.refused if self.feed else 0,
                "unknown_writer": self.feed.unknown_writer if self.feed else 0,
                "bad_input": self.feed.bad_input if self.feed else 0, "lost": self.feed.lost if self.feed else 0}

    def info(self) -> Dict[str, Any]:
        """This import in the node's ``microsRtInfo`` (section ``relay``): the exporting relays seen now are
        those whose DDS writers of the outside topic discovery knows."""
        from micros_rt.transports.dds.types import dds_topic_name

        exporters = sorted({t.get("node", "") for t in self._relay._directory.tags(dds_topic_name(self.rule.outside))
                            if t.get("relay") == self.rule.origin and t.get("graph") != self._relay.graph_id} - {""})
        options = self.rule.options
        return {"outside": self.rule.outside, "local": self.rule.local, "origin": self.rule.origin,
                "exporters": exporters, "protocol": "DDS", "process": self._relay.node,
                "qos": None if options is None else options.to_dict(), "queue_size": self.rule.queue_size,
                "latch": self.rule.latch, "counters": self.stats(),
                "straight": self.pub.get_delegated_dds_connections()}

    def close(self) -> None:
        self.sub.unregister()
        if self.feed is not None:
            self.feed.close()
        self.pub.unregister()


class _ServiceExport:
    """One service of this graph announced to the others (see :mod:`.services`)."""

    def __init__(self, relay: "Relay", name: str, uri: str, header: Dict[str, str]) -> None:
        from std_msgs.msg import String

        self.name, self.uri = name, uri
        self.outside = relay.config.outside_name(name)
        tag = {"graph": relay.graph_id, "node": relay.node, "relay": relay.config.graph, "service": self.outside,
               "uri": uri, "type": header.get("type", ""), "md5": header.get("md5sum", "")}
        self.writer = relay.backend.open_writer(EndpointSpec(ANNOUNCE_TOPIC, String, 1, False, tag),
                                                micros_rt.AdvertiseQoSOptions())

    def stats(self) -> Dict[str, Any]:
        return {"service": self.name, "as": self.outside, "uri": self.uri}

    def close(self) -> None:
        self.writer.close()


class _ServiceImport:
    """Another graph's service offered in this graph; each call is forwarded to the announced server."""

    def __init__(self, relay: "Relay", rule: ServiceImport, service_class: Any) -> None:
        self.rule = rule
        self.uri = ""
        self.calls = self.failed = 0
        self._relay = relay
        self._class = service_class
        self.service = rospy.Service(rule.local, service_class, self._call)

    def _call(self, request: Any) -> Any:
        self.calls += 1
        if not self.uri:
            self.failed += 1
            raise rospy.ServiceException(f"{self.rule.outside}: graph {self.rule.origin} does not offer this service "
                                         f"now (its relay or server is gone)")
        try:
            # the name the server has in its own graph: /robot_a/add_two_ints -> /add_two_ints
            return call_service(self.uri, "/" + self.rule.outside.split("/", 2)[2], self._class, request,
                                caller_id=self._relay.node, timeout=self.rule.timeout)
        except ServiceCallError as exc:
            self.failed += 1
            raise rospy.ServiceException(f"{self.rule.outside} (graph {self.rule.origin}, {self.uri}): {exc}") from None

    def stats(self) -> Dict[str, Any]:
        return {"service": self.rule.outside, "as": self.rule.local, "calls": self.calls, "failed": self.failed,
                "uri": self.uri}

    def close(self) -> None:
        self.service.shutdown("relay closing")


class Relay:
    """Runs a :class:`~micros_rt.bridges.relay.config.RelayConfig` in this process's node (``init_node``
    first). ``start()`` begins; topics are set up as they appear; ``close()`` ends."""

    def __init__(self, config: RelayConfig, *, poll_period: float = 1.0,
                 event_cb: Optional[Callable[..., None]] = None, share: Share = Share()) -> None:
        backend = dds_backend()
        if backend is None:
            raise micros_rt.DDSUnavailableError("the relay carries topics between graphs over DDS, and DDS did not "
                                                "start in this process (see the warning above)")
        from micros_rt.transports.dds.feed import WriterDirectory

        info = micros_rt.node_info()
        self.config = config
        self.share = share
        self.backend = backend
        self.node = info.name
        self.graph_id = info.graph
        self.nh = micros_rt.NodeHandle()
        self.poll_period = poll_period
        self._event_cb = event_cb
        self.exports: Dict[str, _Export] = {}
        self.imports: Dict[str, _Import] = {}
        self.service_exports: Dict[str, _ServiceExport] = {}
        self.service_imports: Dict[str, _ServiceImport] = {}
        self._refused: Dict[str, str] = {}   # topic -> why it is not carried (said once)
        self._directory = WriterDirectory(backend)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="micros_rt relay", daemon=True)
        self._lock = threading.Lock()
        #: the ``ros2:`` section (the first process carries it, with the imports)
        self.ros2 = Ros2Side(self, config.ros2) if config.ros2 and share.imports else None

    def start(self) -> "Relay":
        register_info_section("relay", self.info)   # what the micros-rt tools show of this relay
        self._thread.start()
        return self

    def __enter__(self) -> "Relay":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the set-up loop -----------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set() and not rospy.is_shutdown():
            try:
                self.poll()
            except Exception as exc:  # the master away for a moment: try again next round
                _log.warning("micros_rt: relay %s: %s (trying again in %.0f s)", self.config.graph, exc,
                             self.poll_period)
            self._stop.wait(self.poll_period)

    def poll(self) -> None:
        """One round: export topics that appeared, import topics whose exporter was discovered."""
        local_types = dict(rospy.get_published_topics())
        import_names = {rule.local for rule in self.config.imports}
        import_names |= {e.ros1_name for e in self.config.ros2 if e.direction == "import"}
        for topic, type_name in sorted(local_types.items()):
            if topic in self.exports or topic in import_names:
                continue
            export = best_match(((r.pattern, r) for r in self.config.exports), topic)
            if export is not None and (self.share.exports is None
                                       or int(export.options.transport_priority) in self.share.exports):
                self._try(topic, lambda: self._export(export, topic, type_name))
        if not self.share.imports:
            return
        pending = [incoming for incoming in self.config.imports if incoming.outside not in self.imports]
        in_use = _types_in_use() if pending else {}
        for incoming in pending:
            self._try(incoming.outside, lambda: self._import(incoming, in_use.get(incoming.local)))
        for name in self.config.export_services:
            self._try(name, lambda: self._export_service(name))
        if self.config.import_services:
            self._import_services()
        if self.ros2 is not None:
            self.ros2.poll(GraphState.ask(rospy.get_master()), self._try)

    def _try(self, topic: str, make: Callable[[], Optional[str]]) -> None:
        try:
            why = make()
        except micros_rt.MicrosRtError as exc:
            why = str(exc)
        if why is not None and self._refused.get(topic) != why:
            self._refused[topic] = why
            _log.error("micros_rt: relay %s: %s", self.config.graph, why)

    def _export(self, rule: ExportRule, topic: str, type_name: str) -> Optional[str]:
        data_class = installed_class(type_name)
        if data_class is None:
            try:  # not installed here: the definition its publishers send
                data_class = learn_from_publisher(rospy.get_master(), topic, caller_id=self.node)
            except TypeLearningError as exc:
                return (f"cannot export {topic}: its type {type_name} is not installed on this host and was not "
                        f"learnt from a publisher: {exc}")
            _log.info("micros_rt: relay %s: learnt %s from a publisher of %s (its package is not installed here)",
                      self.config.graph, type_name, topic)
        with self._lock:
            self.exports[topic] = export = _Export(self, rule, topic, data_class)
        _log.info("micros_rt: relay %s: exporting %s (%s) as %s", self.config.graph, topic, type_name,
                  export.outside)
        return None

    def _import(self, rule: ImportRule, local_type: Optional[str]) -> Optional[str]:
        from micros_rt.transports.dds.types import dds_topic_name

        tags = [t for t in self._directory.tags(dds_topic_name(rule.outside))
                if t.get("relay") == rule.origin and t.get("type")]
        if not tags:
            return None  # the exporting relay is not there (yet): nothing to say, it may come later
        type_name = tags[0]["type"]
        if local_type is not None and local_type != type_name:
            return (f"cannot import {rule.outside} as {rule.local}: graph {rule.origin} sends {type_name}, and "
                    f"{rule.local} is {local_type} in this graph (its publishers or subscribers use that type); "
                    f"give the import another name with 'as:', or fix the type on one side")
        data_class = installed_class(type_name)
        if data_class is None:
            try:  # not installed here: the definition in the exporter's tag
                data_class = class_from_definition(type_name, tags[0].get("md5", ""), tags[0].get("def", ""),
                                                   compressed=True)
            except TypeLearningError as exc:
                return (f"cannot import {rule.outside}: its type {type_name} is not installed on this host, and "
                        f"{exc}")
        if tags[0].get("md5") and tags[0]["md5"] != data_class._md5sum:
            return (f"cannot import {rule.outside}: graph {rule.origin} has another definition of {type_name} "
                    f"(md5 {tags[0]['md5']}, here {data_class._md5sum}); build both from the same message package")
        if tags[0].get("best_effort") == "1" and not (rule.options and rule.options.using_best_effort_protocol):
            # a reliable reader does not match a best-effort writer: take it as it is sent
            rule = dataclasses.replace(rule, options=dataclasses.replace(rule.options or SubscribeQoSOptions(),
                                                                         using_best_effort_protocol=True))
        with self._lock:
            self.imports[rule.outside] = _Import(self, rule, data_class)
        _log.info("micros_rt: relay %s: importing %s (%s) as %s", self.config.graph, rule.outside, type_name,
                  rule.local)
        return None

    def _export_service(self, name: str) -> Optional[str]:
        """Announce ``name`` while this graph's master knows a server for it (again when it moved)."""
        try:
            uri = str(rospy.get_master().lookupService(name)[2] or "")
        except Exception as exc:  # the master away: keep what is announced, try again next round
            return f"cannot look up service {name}: {exc}"
        current = self.service_exports.get(name)
        if current is not None and current.uri == uri:
            return None
        if current is not None:
            current.close()  # the server went away or moved: withdraw, then announce the new one
            with self._lock:
                del self.service_exports[name]
        if not uri.startswith("rosrpc://"):
            return None  # not served now
        try:
            header = probe_service(uri, name, caller_id=self.node, timeout=5.0)
        except ServiceCallError as exc:
            return f"cannot export service {name}: {exc}"
        with self._lock:
            self.service_exports[name] = _ServiceExport(self, name, uri, header)
        _log.info("micros_rt: relay %s: exporting service %s (%s, served at %s)", self.config.graph, name,
                  header.get("type"), uri)
        return None

    def _import_services(self) -> None:
        from micros_rt.transports.dds.types import dds_topic_name

        offered: Dict[str, Dict[str, str]] = {}
        for announced in self._directory.tags(dds_topic_name(ANNOUNCE_TOPIC)):
            if announced.get("service") and announced.get("relay") and announced.get("graph") != self.graph_id:
                offered[announced["service"]] = announced
        for rule in self.config.import_services:
            found = offered.get(rule.outside)
            tag = found if found is not None and found.get("relay") == rule.origin else None
            existing = self.service_imports.get(rule.outside)
            if existing is not None:
                existing.uri = tag["uri"] if tag else ""   # a server that moved or went
                continue
            if tag is not None:
                self._try(rule.outside, lambda: self._import_service(rule, tag))

    def _import_service(self, rule: ServiceImport, tag: Dict[str, str]) -> Optional[str]:
        try:
            service_class = roslib.message.get_service_class(tag.get("type", ""))
        except (ValueError, ImportError):
            service_class = None
        if service_class is None:
            try:  # not installed here: forward the calls as bytes, under the type and md5 the server announced
                service_class = raw_service_class(tag.get("type", ""), tag.get("md5", ""))
            except TypeLearningError as exc:
                return f"cannot import service {rule.outside}: its type is not installed on this host, and {exc}"
            _log.info("micros_rt: relay %s: service %s: %s is not installed here; its calls are forwarded as bytes",
                      self.config.graph, rule.outside, tag.get("type"))
        if tag.get("md5") and tag["md5"] != service_class._md5sum:
            return (f"cannot import service {rule.outside}: graph {rule.origin} has another definition of "
                    f"{tag.get('type')} (md5 {tag['md5']}, here {service_class._md5sum})")
        imported = _ServiceImport(self, rule, service_class)
        imported.uri = tag["uri"]
        with self._lock:
            self.service_imports[rule.outside] = imported
        _log.info("micros_rt: relay %s: importing service %s as %s", self.config.graph, rule.outside, rule.local)
        return None

    # -- reporting and shutdown ----------------------------------------------------------------------
    def event(self, kind: str, **fields: Any) -> None:
        """Tell the program's ``event_cb`` (``micros-rt relay --json`` prints it) of a deadline miss or a
        recovery."""
        if self._event_cb is not None:
            self._event_cb(kind, **fields)

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            exports, imports = list(self.exports.values()), list(self.imports.values())
            services: List[Any] = [*self.service_exports.values(), *self.service_imports.values()]
        snapshot = {"graph": self.config.graph, "exports": [e.stats() for e in exports],
                    "imports": [i.stats() for i in imports],
                    "services": [s.stats() for s in services], "not_carried": dict(self._refused)}
        if self.ros2 is not None:
            snapshot["ros2"] = self.ros2.stats()
        return snapshot

    def info(self) -> Dict[str, Any]:
        """The ``relay`` section of this node's ``microsRtInfo``: the graph, this process's place among the
        relay's processes, and what it carries (each export and import with its QoS and counters)."""
        with self._lock:
            exports, imports = list(self.exports.values()), list(self.imports.values())
        info = {"graph": self.config.graph, "node": self.node, "parent": self.share.parent,
                "children": list(self.share.children), "exports": [e.info() for e in exports],
                "imports": [i.info() for i in imports], "not_carried": dict(self._refused)}
        if self.ros2 is not None:
            info["ros2"] = self.ros2.stats()
        return info

    def close(self) -> None:
        unregister_info_section("relay")
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        with self._lock:
            endpoints: List[Any] = [*self.exports.values(), *self.imports.values(),
                                    *self.service_exports.values(), *self.service_imports.values()]
            self.exports.clear()
            self.imports.clear()
            self.service_exports.clear()
            self.service_imports.clear()
        if self.ros2 is not None:
            self.ros2.close()
        for endpoint in endpoints:
            try:
                endpoint.close()
            except Exception as exc:  # a master gone at shutdown: unregistering fails, nothing is left open
                _log.debug("micros_rt: relay: closing: %s", exc)


def _types_in_use() -> Dict[str, str]:
    """This graph's topics that have a publisher or a subscriber now, with the type the master has for them
    (a subscriber's too: an import must not be published under another type than the graph's subscribers
    expect, each of whom would refuse it on its md5)."""
    master = rospy.get_master()
    _code, _msg, (publishers, subscribers, _services) = master.getSystemState()
    _code, _msg, types = master.getTopicTypes()
    present = {topic for topic, nodes in (*publishers, *subscribers) if nodes}
    return {topic: type_name for topic, type_name in types if topic in present and type_name != "*"}
