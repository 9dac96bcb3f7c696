"""The live ROS graph as the ``micros-rt`` tools see it: the master's view, every node's ``getBusInfo``, and
for micros_rt nodes their ``microsRtInfo`` (QoS, links, the negotiation's verdicts; see
:mod:`micros_rt.core.introspection`). Stock nodes have no ``microsRtInfo``: their links are TCPROS.

Collecting (:func:`snapshot`) does the network calls; joining the answers into links (:func:`build_links`)
and describing QoS (:func:`describe_publisher_qos`, ...) are pure functions.

A ``micros-rt relay`` node's answer has a ``relay`` section (what it carries between graphs):
:func:`relay_marking` turns it into how the tools mark the relay's subscription of an exported topic
("relayed out as /robot_a/chatter ...") and its publication of an imported one ("relayed in from graph ...").
"""

from __future__ import annotations

import concurrent.futures
import json
import os
import time
import xmlrpc.client
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from ..core.introspection import INFO_METHOD
# the library's XML-RPC transport with a per-connection timeout (the micros_rt package imports rospy anyway)
from ..transports.tcpros.xmlrpc import TimeoutTransport
from ..exceptions import MicrosRtError
from ..qos.options import describe, drop_counters
from . import CommandError

__all__ = [
    "CALLER_ID",
    "GraphSnapshot",
    "Link",
    "Master",
    "NodeReport",
    "build_links",
    "describe_publisher_qos",
    "describe_subscriber_qos",
    "master_uri",
    "pacing_of",
    "probe_node",
    "relay_marking",
    "resolve_topic",
    "snapshot",
]

CALLER_ID = "/micros_rt_cli"
NODE_TIMEOUT = 3.0
MICROS_RT = "micros_rt"
STOCK = "stock"
UNREACHABLE = "unreachable"


def master_uri(env: Mapping[str, str] = os.environ) -> str:
    """``ROS_MASTER_URI`` as ROS tools read it (default ``http://localhost:11311/``)."""
    return env.get("ROS_MASTER_URI", "").strip() or "http://localhost:11311/"


def resolve_topic(name: str, env: Mapping[str, str] = os.environ) -> str:
    """A topic name as ``rostopic`` resolves a command-line name: relative names go under ``ROS_NAMESPACE``."""
    if not name or any(c.isspace() for c in name):
        raise CommandError(f"invalid topic name {name!r}")
    if name.startswith("/"):
        return name
    ns = env.get("ROS_NAMESPACE", "/").strip() or "/"
    return "/" + "/".join(p for p in (ns.strip("/"), name.lstrip("~")) if p)


def _proxy(uri: str, timeout: float) -> xmlrpc.client.ServerProxy:
    return xmlrpc.client.ServerProxy(uri, transport=TimeoutTransport(timeout))


def ros_call(uri: str, method: str, *args: Any, timeout: float = NODE_TIMEOUT) -> Any:
    """Call a ROS XML-RPC API; the value of ``[code, status, value]``. Raises ``OSError``,
    ``xmlrpc.client.Error`` or ``ValueError`` (code != 1, with the status)."""
    code, status, value = getattr(_proxy(uri, timeout), method)(CALLER_ID, *args)
    if code != 1:
        raise ValueError(f"{method}: {status}")
    return value


class Master:
    """The ROS master at ``uri``; an unreachable master is a :class:`CommandError` naming the fix."""

    def __init__(self, uri: Optional[str] = None, *, timeout: float = 5.0) -> None:
        self.uri = uri or master_uri()
        self.timeout = timeout

    def call(self, method: str, *args: Any) -> Any:
        try:
            return ros_call(self.uri, method, *args, timeout=self.timeout)
        except (OSError, xmlrpc.client.ProtocolError) as exc:
            reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            raise CommandError(f"cannot reach the ROS master at {self.uri} ({reason}); start roscore, or "
                               f"set ROS_MASTER_URI to the running master") from None
        except (xmlrpc.client.Error, ValueError) as exc:
            raise CommandError(f"the ROS master at {self.uri} answered {method} with an error: {exc}") from None

    def system_state(self) -> Tuple[Dict[str, List[str]], Dict[str, List[str]]]:
        """(publishers, subscribers): topic -> node names."""
        pubs, subs, _srvs = self.call("getSystemState")
        return {t: list(n) for t, n in pubs}, {t: list(n) for t, n in subs}

    def topic_types(self) -> Dict[str, str]:
        return {t: ty for t, ty in self.call("getTopicTypes")}

    def lookup_node(self, name: str) -> Optional[str]:
        try:
            return str(ros_call(self.uri, "lookupNode", name, timeout=self.timeout))
        except (OSError, xmlrpc.client.Error, ValueError):
            return None


@dataclass
class NodeReport:
    """One node as probed: ``kind`` is micros_rt, stock or unreachable."""

    name: str
    uri: Optional[str]
    kind: str
    bus: List[List[Any]] = field(default_factory=list)   # getBusInfo entries
    info: Optional[Dict[str, Any]] = None                # microsRtInfo value (micros_rt nodes)
    clock_offset: Optional[float] = None                  # its wall clock minus ours, seconds
    clock_error: Optional[float] = None                   # +- half the call's round trip
    error: str = ""

    def publication(self, topic: str) -> Optional[Dict[str, Any]]:
        return _find(self.info, "publications", topic)

    def subscription(self, topic: str) -> Optional[Dict[str, Any]]:
        return _find(self.info, "subscriptions", topic)

    def relay(self) -> Optional[Dict[str, Any]]:
        """The ``relay`` section of a ``micros-rt relay`` node's answer (None for any other node)."""
        section = (self.info or {}).get("relay")
        return section if isinstance(section, dict) and "error" not in section else None


def _find(info: Optional[Dict[str, Any]], section: str, topic: str) -> Optional[Dict[str, Any]]:
    for item in (info or {}).get(section, []):
        if item.get("topic") == topic:
            return dict(item)
    return None


def probe_node(name: str, uri: Optional[str], *, timeout: float = NODE_TIMEOUT) -> NodeReport:
    """Ask a node for ``microsRtInfo`` (micros_rt) and ``getBusInfo`` (every ROS node)."""
    if uri is None:
        return NodeReport(name, None, UNREACHABLE, error="the master does not know its URI")
    report = NodeReport(name, uri, STOCK)
    try:
        report.bus = [list(e) for e in ros_call(uri, "getBusInfo", timeout=timeout)]
    except (OSError, xmlrpc.client.Error, ValueError) as exc:
        return NodeReport(name, uri, UNREACHABLE, error=f"getBusInfo failed: {exc}")
    t0 = time.time()
    try:
        text = ros_call(uri, INFO_METHOD, timeout=timeout)
    except ValueError as exc:  # a micros_rt node that could not collect its info (closing, say)
        report.kind, report.error = MICROS_RT, str(exc)
        return report
    except (OSError, xmlrpc.client.Error):
        return report  # a fault: no such method, a stock node
    t1 = time.time()
    try:
        info = json.loads(text)
    except (TypeError, ValueError):
        return report
    if isinstance(info, dict):
        report.kind, report.info = MICROS_RT, info
        if isinstance(info.get("time"), (int, float)):
            report.clock_offset = float(info["time"]) - (t0 + t1) / 2
            report.clock_error = (t1 - t0) / 2
    return report


@dataclass
class Link:
    """One publisher-to-subscriber connection of a topic."""

    topic: str
    publisher: str
    subscriber: str
    protocol: str
    publisher_kind: str
    subscriber_kind: str
    publisher_qos: Optional[Dict[str, Any]] = None
    subscriber_qos: Optional[Dict[str, Any]] = None
    transport_priority: Optional[str] = None
    #: for a TCPROS link: why not DDS, in words (the publisher's own verdict between two micros_rt nodes)
    reason: Optional[str] = None
    #: the negotiation's verdict kind when the publisher judged a DDS offer of this subscriber
    verdict: Optional[str] = None
    matched: Optional[bool] = None  # DDS: has discovery matched the subscriber's reader yet
    #: the link's ends as relays mark them (:func:`relay_marking`): the subscriber exporting the topic to other
    #: graphs, the publisher importing it from one; empty for links between ordinary nodes
    relayed: List[Dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> Dict[str, Any]:
        out = asdict(self)
        if not self.relayed:
            del out["relayed"]   # the JSON of links between ordinary nodes stays as it was
        return out


@dataclass
class GraphSnapshot:
    master: str
    types: Dict[str, str]
    publishers: Dict[str, List[str]]
    subscribers: Dict[str, List[str]]
    nodes: Dict[str, NodeReport]
    links: List[Link]

    def endpoint(self, node: str, topic: str, *, publisher: bool) -> Dict[str, Any]:
        """A publisher or subscriber of ``topic`` as the tools print it."""
        report = self.nodes.get(node) or NodeReport(node, None, UNREACHABLE)
        ep = report.publication(topic) if publisher else report.subscription(topic)
        qos = _endpoint_qos(ep)
        out = {"node": node, "uri": report.uri, "kind": report.kind, "qos": qos,
               "description": _describe(report, qos, publisher=publisher)}
        marking = relay_marking(report, topic, publisher=publisher)
        if marking is not None:
            out["relay"] = marking
        paced = pacing_of(report, topic) if publisher else None
        if paced is not None:
            out["paced"] = paced
        return out


def _endpoint_qos(ep: Optional[Dict[str, Any]]) -> Optional[Dict[str, Any]]:
    if ep is None:
        return None
    qos = dict(ep.get("qos") or {})
    qos["queue_size"] = ep.get("queue_size")
    if "latch" in ep:
        qos["latch"] = ep["latch"]
    if "hints" in ep:
        qos["hints"] = list(ep["hints"])
    return qos


def _describe(report: NodeReport, qos: Optional[Dict[str, Any]], *, publisher: bool) -> str:
    kind = report.kind
    if kind == MICROS_RT and report.info is None:
        return f"micros_rt node whose QoS is unknown ({report.error})"
    if kind == STOCK:
        return "stock ROS endpoint (TCPROS only, no micros_rt QoS)"
    if kind == UNREACHABLE:
        return "unreachable (its node does not answer)"
    if qos is None:  # rospy's own endpoint in a micros_rt process (actionlib's, a relay's action)
        return "rospy endpoint of a micros_rt node (TCPROS only, no micros_rt QoS)"
    return describe_publisher_qos(qos) if publisher else describe_subscriber_qos(qos)


def _queue(qos: Mapping[str, Any]) -> str:
    q = qos.get("queue_size")
    return "lossless (queue_size None)" if not q else f"queue {q}"


def _option_words(qos: Mapping[str, Any], side: str) -> List[str]:
    try:
        return describe(qos, side)
    except MicrosRtError as exc:  # a peer's QoS that does not parse: say so, do not fail the whole report
        return [f"QoS not understood ({exc})"]


def describe_publisher_qos(qos: Mapping[str, Any]) -> str:
    """``AdvertiseQoSOptions.to_dict()`` (+ queue_size, latch) in a few words (the words are the catalogue's,
    :data:`micros_rt.qos.options.OPTIONS`).

    >>> describe_publisher_qos({"transport_priority": "HIGH", "using_best_effort_protocol": True, "queue_size": None})
    'best effort, priority HIGH, lossless (queue_size None)'
    """
    parts = _option_words(qos, "advertise")
    if qos.get("latch"):
        parts.append("latched")
    if "queue_size" in qos:
        parts.append(_queue(qos))
    return ", ".join(parts)


def describe_subscriber_qos(qos: Mapping[str, Any]) -> str:
    """``SubscribeQoSOptions.to_dict()`` (+ queue_size, hints) in a few words.

    >>> describe_subscriber_qos({"deadline": 0.5, "ordered_by_sending_timestamp": False, "queue_size": 10})
    'reliable, deadline 500 ms, by arrival, queue 10'
    """
    parts = _option_words(qos, "subscribe")
    if "queue_size" in qos:
        parts.append(_queue(qos))
    hints = qos.get("hints")
    if hints and list(hints) != ["DDS", "TCPROS"]:
        parts.append("hints " + ",".join(hints))
    return ", ".join(parts)


def _rate(value: Any) -> str:
    return "no max_rate" if value is None else f"max_rate {float(value):g} Hz"


def pacing_of(report: NodeReport, topic: str) -> Optional[Dict[str, Any]]:
    """The TCPROS connections of ``topic`` that ``report``'s node paces across its profile's links (its
    ``microsRtInfo``'s ``links``), with a ``description`` in words; None when it paces none of them.

    >>> r = NodeReport("/camera", None, MICROS_RT, info={"links": [{"link": "radio", "connections": [
    ...     {"topic": "/image", "peer": "10.0.0.2", "rate_bps": 36e6, "used_bps": 35.1e6}]}]})
    >>> pacing_of(r, "/image")["description"]
    'paced on link radio: TCPROS to 10.0.0.2 at 36 Mbit/s (used 35.1)'
    """
    found = [(link.get("link", "?"), c) for link in (report.info or {}).get("links") or []
             for c in link.get("connections") or [] if c.get("topic") == topic]
    if not found:
        return None
    parts = [f"paced on link {name}: TCPROS to {c.get('peer')} at {float(c.get('rate_bps', 0)) / 1e6:.3g} Mbit/s "
             f"(used {float(c.get('used_bps', 0)) / 1e6:.3g})" for name, c in found]
    return {"connections": [dict(c, link=name) for name, c in found], "description": "; ".join(parts)}


def relay_marking(report: NodeReport, topic: str, *, publisher: bool) -> Optional[Dict[str, Any]]:
    """How a relay node's end of ``topic`` is marked: its subscription of a topic it exports (``direction``
    ``out``) or its publication of a topic it imports (``in``), with a ``description`` in words; None when
    ``report`` is no relay or does not carry ``topic`` that way.

    >>> r = NodeReport("/relay_robot_a", None, MICROS_RT, info={"relay": {"graph": "robot_a", "exports": [
    ...     {"topic": "/chatter", "outside": "/robot_a/chatter", "qos": {"transport_priority": "HIGH"},
    ...      "max_rate": 5, "counters": {"received": 9, "sent": 5, "rate_capped": 4}}]}})
    >>> relay_marking(r, "/chatter", publisher=False)["description"]
    'relayed out as /robot_a/chatter (DDS, HIGH, reliable, max_rate 5 Hz) by relay node /relay_robot_a; sent 5 of 9 received (rate capped 4)'
    """
    section = report.relay()
    if section is None:
        return None
    graph = str(section.get("graph", "?"))
    parent = section.get("parent")
    process = f" (a process of relay {parent})" if parent else ""
    if not publisher:
        for ex in section.get("exports") or []:
            if ex.get("topic") != topic:
                continue
            qos = ex.get("qos") or {}
            counters = dict(ex.get("counters") or {})
            how = ", ".join([str(ex.get("protocol", "DDS")), str(qos.get("transport_priority", "NORMAL")),
                             "best effort" if qos.get("using_best_effort_protocol") else "reliable",
                             _rate(ex.get("max_rate"))])
            dropped = [f"{label} {counters[key]}" for key, label in (
                ("rate_capped", "rate capped"), ("no_reader", "no reader"), ("superseded", "superseded"),
                ("dropped_queue_full", "queue full"), ("looped", "looped")) if counters.get(key)]
            summary = f"relayed out as {ex.get('outside')} ({how}) by relay node {report.name}{process}"
            text = (f"{summary}; sent {counters.get('sent', 0)} of {counters.get('received', 0)} received"
                    + (f" ({', '.join(dropped)})" if dropped else ""))
            return {"direction": "out", "relay_node": report.name, "relay": parent or report.name, "graph": graph,
                    "outside": ex.get("outside"), "protocol": ex.get("protocol", "DDS"),
                    "transport_priority": qos.get("transport_priority"), "max_rate": ex.get("max_rate"),
                    "counters": counters, "summary": summary, "description": text}
        return None
    for im in section.get("imports") or []:
        if im.get("local") != topic:
            continue
        counters = dict(im.get("counters") or {})
        exporters = [str(e) for e in im.get("exporters") or []]
        seen = f"exported by {', '.join(exporters)}" if exporters else "no exporting relay seen now"
        dropped = [f"{key.removeprefix('dropped_').replace('_', ' ')} {counters[key]}" for key in (
            "dropped_queue_full", *drop_counters(), "refused", "unknown_writer", "bad_input", "lost")
            if counters.get(key)]
        summary = (f"relayed in from graph {im.get('origin')} (outside topic {im.get('outside')}, {seen}) by relay "
                   f"node {report.name}")
        straight = int(im.get("straight") or 0)
        text = (f"{summary}; published {counters.get('published', 0)} of {counters.get('received', 0)} received"
                + (f" ({', '.join(dropped)})" if dropped else "")
                + (f"; {straight} micros_rt subscriber{'s' if straight != 1 else ''} read{'' if straight != 1 else 's'} "
                   f"it straight from graph {im.get('origin')}'s relay" if straight else ""))
        return {"direction": "in", "relay_node": report.name, "relay": report.name, "graph": graph,
                "origin": im.get("origin"), "outside": im.get("outside"), "exporters": exporters, "straight": straight,
                "protocol": im.get("protocol", "DDS"), "counters": counters, "summary": summary, "description": text}
    return None


def _shm_reason(pub: NodeReport, sub: NodeReport, topic: str) -> str:
    """Why this link is shared memory (the negotiation's rule, and what the subscriber asked for)."""
    hints = list((sub.subscription(topic) or {}).get("hints") or [])
    asked = f"; the subscriber's TransportHints: {', '.join(hints)}" if hints else ""
    return (f"both nodes run on this host as the same Unix user, so the message goes through a shared-memory "
            f"channel of their own (iceoryx2), not a socket{asked}")


def _tcpros_reason(pub: NodeReport, sub: NodeReport, topic: str) -> Tuple[str, Optional[str]]:
    """(why this link is TCPROS, verdict kind or None)."""
    for node in (pub, sub):
        if node.kind == MICROS_RT and node.info is None:
            return f"unknown: micros_rt node {node.name} did not say ({node.error})", None
    for node, side, ep in ((pub, "publisher", pub.publication(topic)), (sub, "subscriber", sub.subscription(topic))):
        if node.kind != MICROS_RT:
            return f"the {side} is a stock ROS node (TCPROS only)", None
        if ep is None:
            return f"the {side} is rospy's own endpoint in a micros_rt node (actionlib's, say: TCPROS only)", None
    publication = pub.publication(topic) or {}
    verdict = (publication.get("verdicts") or {}).get(sub.name)
    if isinstance(verdict, dict) and not verdict.get("accepted"):
        return str(verdict.get("reason", "DDS declined")), str(verdict.get("kind", ""))
    subscription = sub.subscription(topic) or {}
    hints = list(subscription.get("hints") or [])
    if "DDS" not in hints:
        return "the subscriber's TransportHints allow only TCPROS", None
    if hints and hints[0] != "DDS":
        return "the subscriber's TransportHints prefer TCPROS (.tcp() before .dds())", None
    if not subscription.get("dds_reader"):
        return "DDS is unavailable in the subscriber's process (see its log)", None
    if publication.get("dds_topic") is None:
        return "DDS is unavailable in the publisher's process (see its log)", None
    if isinstance(verdict, dict):
        return "DDS was accepted, but its DDS link was dropped (reader not discovered in time?)", "accepted"
    return "no DDS offer from this subscriber reached the publisher", None


def build_links(topic: str, publishers: Sequence[str], subscribers: Sequence[str],
                nodes: Mapping[str, NodeReport]) -> List[Link]:
    """Every publisher-to-subscriber link of ``topic`` from the nodes' ``getBusInfo`` (publisher side
    first, the subscriber side for publishers that did not answer) joined with ``microsRtInfo``."""
    by_uri = {r.uri.rstrip("/"): r.name for r in nodes.values() if r.uri}
    pairs: Dict[Tuple[str, str], Tuple[str, bool]] = {}  # (pub, sub) -> (protocol, seen from publisher)
    for p in publishers:
        for entry in (nodes[p].bus if p in nodes else []):
            if len(entry) >= 5 and entry[2] == "o" and entry[4] == topic:
                pairs.setdefault((p, str(entry[1])), (str(entry[3]), True))
    for s in subscribers:
        for entry in (nodes[s].bus if s in nodes else []):
            if len(entry) >= 5 and entry[2] == "i" and entry[4] == topic:
                pub_name = by_uri.get(str(entry[1]).rstrip("/"), str(entry[1]))
                pairs.setdefault((pub_name, s), (str(entry[3]), False))
    links = []
    for (p, s), (protocol, _) in sorted(pairs.items()):
        pub = nodes.get(p) or NodeReport(p, None, UNREACHABLE)
        sub = nodes.get(s) or NodeReport(s, None, UNREACHABLE)
        pub_qos = _endpoint_qos(pub.publication(topic))
        link = Link(topic, p, s, protocol, pub.kind, sub.kind, pub_qos, _endpoint_qos(sub.subscription(topic)),
                    transport_priority=str(pub_qos.get("transport_priority")) if pub_qos else None)
        link.relayed = [m for m in (relay_marking(pub, topic, publisher=True),
                                    relay_marking(sub, topic, publisher=False)) if m is not None]
        if protocol == "DDS":
            for item in (pub.publication(topic) or {}).get("links", []):
                if item.get("subscriber") == s and "matched" in item:
                    link.matched = bool(item["matched"])
        elif protocol == "SHM":
            link.reason = _shm_reason(pub, sub, topic)
        else:
            link.reason, link.verdict = _tcpros_reason(pub, sub, topic)
        links.append(link)
    return links


def probe_all(master: Master, names: Iterable[str]) -> Dict[str, NodeReport]:
    """Probe nodes in parallel (each call bounded by :data:`NODE_TIMEOUT`)."""
    names = sorted(set(names))
    if not names:
        return {}
    with concurrent.futures.ThreadPoolExecutor(max_workers=min(16, len(names))) as pool:
        uris = dict(zip(names, pool.map(master.lookup_node, names)))
        reports = pool.map(lambda n: probe_node(n, uris[n]), names)
        return {r.name: r for r in reports}


def snapshot(master: Master, topics: Optional[Iterable[str]] = None) -> GraphSnapshot:
    """The graph (or only ``topics``): the master's state, every node involved probed, links built."""
    pubs, subs = master.system_state()
    types = master.topic_types()
    wanted = set(topics) if topics is not None else set(pubs) | set(subs) | set(types)
    names = {n for t in wanted for n in pubs.get(t, []) + subs.get(t, [])}
    nodes = probe_all(master, names)
    links = [link for t in sorted(wanted) for link in build_links(t, pubs.get(t, []), subs.get(t, []), nodes)]
    return GraphSnapshot(master.uri, types, pubs, subs, nodes, links)

