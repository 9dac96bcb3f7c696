"""``micros-rt graph``: the live graph's nodes and topics, every link coloured by protocol and labelled with
its QoS, as Graphviz (``--dot``) or a picture (``--png``, drawn by Graphviz's ``dot``).

``micros-rt relay`` nodes are drawn as relays (a hexagon, with their graph), and each topic they carry
between graphs gets an edge to (export) or from (import) an ``outside: /robot_a/chatter`` pseudo-node, the
DDS topic other graphs see, labelled ``relay out`` / ``relay in``."""

from __future__ import annotations

import concurrent.futures
import shutil
import subprocess
import sys
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Set

from ..exceptions import MicrosRtError
from ..qos.options import describe
from . import CommandError
from ._args import ArgumentParser
from ._bothgraph import Both, Ros1View
from ._bothinfo import HELPER, RELAY, ROS2, carriage, dds_endpoints, dds_links
from ._ddsgraph import DEFAULT_WAIT, DdsView, discover
from ._graphinfo import MICROS_RT, GraphSnapshot, Master, relay_marking, snapshot

__all__ = ["main", "to_dot", "PROTOCOL_COLOURS"]

#: Link colour per protocol (a colour-blind-safe pair), and for links that carry nothing yet.
PROTOCOL_COLOURS = {"DDS": "#1f77b4", "TCPROS": "#e66100"}
OTHER_COLOUR = "#888888"
#: Relay nodes' fill and their edges to and from other graphs.
RELAY_FILL = "#e4d7f0"
RELAY_COLOUR = "#7b3294"
#: ROS 2 nodes' fill.
ROS2_FILL = "#fde0c5"
#: Plumbing every ROS graph has; shown with --all.
HIDDEN_TOPICS = frozenset({"/rosout", "/rosout_agg", "/parameter_events"})
HIDDEN_NODES = frozenset({"/rosout"})


def main(argv: List[str]) -> int:
    """``micros-rt graph [--png FILE] [--dot [FILE]] [--all]``."""
    parser = ArgumentParser(
        prog="micros-rt graph", usage="%(prog)s [--png FILE.png] [--dot [FILE.dot]] [--all]",
        description="Draw the live ROS graph: nodes (micros_rt or stock) and topics, each publisher->subscriber "
                    "link coloured by its protocol (DDS blue, TCPROS orange) and labelled with its QoS. "
                    "Needs Graphviz's 'dot' for --png.")
    parser.add_argument("--png", metavar="FILE.png", help="write the picture to FILE.png")
    parser.add_argument("--dot", metavar="FILE.dot", nargs="?", const="-",
                        help="write the Graphviz source to FILE.dot (stdout without FILE)")
    parser.add_argument("--all", action="store_true",
                        help="also show /rosout, /parameter_events and hidden ROS 2 names, and their links")
    parser.add_argument("--wait", type=float, default=DEFAULT_WAIT, metavar="SEC",
                        help=f"seconds of DDS discovery for the ROS 2 side (default {DEFAULT_WAIT:g}; 0: ROS 1 only)")
    args = parser.parse_args(argv)
    if not args.png and not args.dot:
        raise CommandError("nothing to draw to: give --png FILE.png and/or --dot [FILE.dot]", code=2)
    if args.wait < 0:
        raise CommandError("--wait must not be negative", code=2)
    master = Master()
    if args.wait == 0:
        snap, view = snapshot(master), None
    else:
        with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
            ros1 = pool.submit(snapshot, master)
            view = discover(args.wait)
            snap = ros1.result()
        if not view.available:
            print(f"micros-rt graph: note: ROS 2 side not drawn: {view.note}", file=sys.stderr)
            view = None
    dot = to_dot(snap, include_all=args.all, ros2=None if view is None else Ros2Side(view, _ours(master)))
    if args.dot == "-":
        sys.stdout.write(dot)
    elif args.dot:
        _write(args.dot, dot)
    if args.png:
        render_png(dot, args.png)
        print(f"wrote {args.png}", file=sys.stderr)
    return 0


def _write(path: str, text: str) -> None:
    try:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from None


def render_png(dot: str, path: str) -> None:
    """Run Graphviz's ``dot -Tpng`` (bounded: 60 s)."""
    exe = shutil.which("dot")
    if exe is None:
        raise CommandError("Graphviz's 'dot' is not installed; apt-get install graphviz (or use --dot)")
    try:
        done = subprocess.run([exe, "-Tpng", "-o", path], input=dot, capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        raise CommandError("Graphviz's dot took longer than 60 s; use --dot and draw it yourself") from None
    if done.returncode != 0:
        first = (done.stderr.strip().splitlines() or [f"exit code {done.returncode}"])[0]
        raise CommandError(f"Graphviz's dot could not write {path}: {first}")


def _q(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _short(qos: Dict[str, object], side: str) -> str:
    try:
        return ", ".join(describe(qos, side, short=True))
    except MicrosRtError:
        return "QoS not understood"


def _short_pub(qos: Dict[str, object]) -> str:
    return _short(qos, "advertise")


def _short_sub(qos: Dict[str, object]) -> str:
    return _short(qos, "subscribe")


def _outside_lines(relays: Dict[str, Dict[str, Any]]) -> List[str]:
    """The ``outside:`` pseudo-nodes (DDS topics between graphs) and the relays' edges to and from them."""
    nodes: Dict[str, str] = {}
    edges: List[str] = []
    for name, section in sorted(relays.items()):
        for ex in section.get("exports") or []:
            outside = str(ex.get("outside"))
            nodes.setdefault(outside, "to other graphs")
            qos = ex.get("qos") or {}
            words = ["relay out", f"{ex.get('protocol', 'DDS')} {qos.get('transport_priority', 'NORMAL')}"
                     + (", best effort" if qos.get("using_best_effort_protocol") else "")]
            if ex.get("max_rate") is not None:
                words.append(f"max_rate {float(ex['max_rate']):g} Hz")
            edges.append(f"  {_q('n:' + name)} -> {_q('o:' + outside)} [label={_q(chr(10).join(words))}, "
                         f"color={_q(RELAY_COLOUR)}, fontcolor={_q(RELAY_COLOUR)}, penwidth=2, style=bold];")
        for im in section.get("imports") or []:
            outside = str(im.get("outside"))
            nodes.setdefault(outside, f"from graph {im.get('origin')}")
            words = ["relay in", f"from graph {im.get('origin')}", f"as {im.get('local')}"]
            edges.append(f"  {_q('o:' + outside)} -> {_q('n:' + name)} [label={_q(chr(10).join(words))}, "
                         f"color={_q(RELAY_COLOUR)}, fontcolor={_q(RELAY_COLOUR)}, penwidth=2, style=bold];")
    return [f"  {_q('o:' + outside)} [label={_q(f'outside: {outside}' + chr(10) + where)}, shape=box, "
            f"style=\"dashed,rounded\", color={_q(RELAY_COLOUR)}];" for outside, where in sorted(nodes.items())] + edges


class Ros2Side:
    """What DDS discovery showed, and which micros_rt tags are this graph's (``Both.ours``)."""

    def __init__(self, view: DdsView, ours: Callable[[Mapping[str, str]], bool]) -> None:
        self.view, self.ours = view, ours

    def topics(self, include_all: bool) -> Set[str]:
        names = {"/" + e.topic[3:] for e in self.view.endpoints if e.topic.startswith("rt/")}
        return {t for t in names if include_all or (t not in HIDDEN_TOPICS and not _hidden(t))}


def _hidden(topic: str) -> bool:
    return any(part.startswith("_") for part in topic.split("/"))


def _ours(master: Master) -> Callable[[Mapping[str, str]], bool]:
    """Whether a micros_rt tag is this master's graph's (as ``topic list`` tells graphs apart)."""
    try:
        run_id = str(master.call("getParam", "/run_id"))
    except CommandError:
        run_id = ""
    return Both(Ros1View(True, uri=master.uri, run_id=run_id), DdsView(True)).ours


def _ros2_node(ep: Mapping[str, Any]) -> str:
    return ("r2:" if ep["kind"] in (ROS2, HELPER) else "n:") + str(ep["node"])


def _ros2_lines(side: Ros2Side, topics: Sequence[str], snap: GraphSnapshot, relays: Dict[str, Dict[str, Any]],
                shown: Set[str]) -> List[str]:
    """ROS 2 nodes (and micros_rt's helpers), their writers' edges to topics, the DDS links from topics to ROS 2
    readers (and to micros_rt readers of ROS 2 writers), and what relays carry between ROS 1 and ROS 2."""
    nodes: Dict[str, str] = {}
    edges: List[str] = []
    for t in topics:
        endpoints = dds_endpoints(side.view, t, side.ours)
        for ep in endpoints:
            if ep["kind"] in (ROS2, HELPER):
                nodes[_ros2_node(ep)] = f"{ep['node']}\n{'ROS 2 node' if ep['kind'] == ROS2 else 'micros_rt helper'}"
        for ep in endpoints:
            if ep["writer"] and ep["kind"] in (ROS2, HELPER):
                edges.append(f"  {_q(_ros2_node(ep))} -> {_q('t:' + t)} [label={_q('ROS 2, ' + ep['qos'])}, "
                             f"color={_q(OTHER_COLOUR)}];")
        for link in dds_links(endpoints):
            if link["subscriber_kind"] == RELAY:
                continue  # the relay's reader of what it carries into ROS 1: drawn as its carriage, below
            target = ("r2:" if link["subscriber_kind"] in (ROS2, HELPER) else "n:") + link["subscriber"]
            if target.startswith("n:") and link["subscriber"] not in shown:
                continue
            words = f"DDS from {link['publisher']}" + ("" if link["matched"] else f"\nnot matched: {link['reason']}")
            colour = PROTOCOL_COLOURS["DDS"] if link["matched"] else OTHER_COLOUR
            style = "" if link["matched"] else ", style=dashed"
            edges.append(f"  {_q('t:' + t)} -> {_q(target)} [label={_q(words)}, color={_q(colour)}, "
                         f"fontcolor={_q(colour)}, penwidth=2{style}];")
    boxes: Dict[str, str] = {}
    for name, section in sorted(relays.items()):
        for entry in section.get("ros2") or []:
            if not isinstance(entry, dict) or not entry.get("kind"):
                continue
            export = entry.get("direction") == "export"
            ros1, ros2 = (entry.get("name"), entry.get("as")) if export else (entry.get("as"), entry.get("name"))
            if entry["kind"] == "topic":
                target = f"t:{ros2}"
                if ros2 not in topics:
                    boxes[target] = f"{ros2}\n(ROS 2)"
            else:
                target = f"r2{entry['kind']}:{ros2}"
                boxes[target] = f"ROS 2 {entry['kind']}\n{ros2}"
                edges += _ros2_call_edges(side, target, str(ros2), str(entry["kind"]), nodes)
            words = (f"relay to ROS 2\n(ROS 1 {ros1})" if export else f"relay from ROS 2\n(into ROS 1 as {ros1})")
            a, b = ("n:" + name, target) if export else (target, "n:" + name)
            edges.append(f"  {_q(a)} -> {_q(b)} [label={_q(words)}, color={_q(RELAY_COLOUR)}, "
                         f"fontcolor={_q(RELAY_COLOUR)}, penwidth=2, style=bold];")
    return ([f"  {_q(key)} [label={_q(label)}, shape=ellipse, style=filled, fillcolor={_q(ROS2_FILL)}];"
             for key, label in sorted(nodes.items())]
            + [f"  {_q(key)} [label={_q(label)}, shape=box, style=\"dashed,rounded\", color={_q(RELAY_COLOUR)}];"
               for key, label in sorted(boxes.items())] + edges)


def _ros2_call_edges(side: Ros2Side, box: str, name: str, kind: str, nodes: Dict[str, str]) -> List[str]:
    """A ROS 2 service's or action's servers (readers of its request topic) and clients (writers) that are ROS 2
    nodes, joined to its box."""
    request = f"rq{name}Request" if kind == "service" else f"rq{name}/_action/send_goalRequest"
    edges = []
    owners = side.view.owners()
    for ep in side.view.endpoints:
        if ep.topic != request or ep.tag is not None or ep.participant in side.view.helpers:
            continue
        node = owners.get(ep.guid)
        key = "r2:" + (node.full_name if node is not None else f"? (participant {ep.participant})")
        nodes.setdefault(key, f"{key[3:]}\nROS 2 node")
        edges.append(f"  {_q(box)} -> {_q(key)} [label=\"client\", color={_q(OTHER_COLOUR)}];" if ep.writer else
                     f"  {_q(key)} -> {_q(box)} [label=\"server\", color={_q(OTHER_COLOUR)}];")
    return edges


def to_dot(snap: GraphSnapshot, *, include_all: bool = False, ros2: Optional[Ros2Side] = None) -> str:
    """Graphviz source for ``snap``: nodes as ellipses, topics as boxes, node->topic per publisher
    (labelled with its QoS), topic->node per link (coloured by protocol, labelled with the publisher,
    the subscriber's QoS and, for a declined DDS offer, the verdict). With ``ros2``, also ROS 2 nodes (DDS
    discovery), their topics and DDS links, and what relays carry between ROS 1 and ROS 2."""
    topics = sorted((t for t in set(snap.publishers) | set(snap.subscribers) if include_all or t not in HIDDEN_TOPICS),
                    key=str)
    if ros2 is not None:
        topics = sorted(set(topics) | ros2.topics(include_all))
    lines = ["digraph micros_rt {", "  rankdir=LR;", '  graph [fontname="Helvetica", fontsize=11, nodesep=0.4];',
             '  node [fontname="Helvetica", fontsize=10];', '  edge [fontname="Helvetica", fontsize=8];']
    shown: Set[str] = set()
    for t in topics:
        shown.update(snap.publishers.get(t, []))
        shown.update(snap.subscribers.get(t, []))
    if not include_all:
        shown -= HIDDEN_NODES
    relays: Dict[str, Dict[str, Any]] = {}
    for name in sorted(shown):
        report = snap.nodes.get(name)
        kind = report.kind if report is not None else "unreachable"
        section = report.relay() if report is not None else None
        if section is not None:
            relays[name] = section
            label = f"{name}\nrelay, graph {section.get('graph', '?')}"
            if section.get("parent"):
                label += f"\nprocess of {section['parent']}"
            lines.append(f"  {_q('n:' + name)} [label={_q(label)}, shape=hexagon, style=filled, "
                         f"fillcolor={_q(RELAY_FILL)}];")
            continue
        fill = "#d6e6f5" if kind == MICROS_RT else "#eeeeee"
        lines.append(f"  {_q('n:' + name)} [label={_q(name + chr(10) + kind)}, shape=ellipse, style=filled, "
                     f"fillcolor={_q(fill)}];")
    lines += _outside_lines(relays)
    if ros2 is not None:
        lines += _ros2_lines(ros2, topics, snap, relays, shown)
    for t in topics:
        in_ros1 = t in snap.publishers or t in snap.subscribers
        kind = snap.types.get(t, "?") if in_ros1 else "ROS 2 only"
        lines.append(f"  {_q('t:' + t)} [label={_q(t + chr(10) + kind)}, shape=box];")
        for pub in sorted(snap.publishers.get(t, [])):
            if pub not in shown:
                continue
            report = snap.nodes.get(pub)
            ep = report.publication(t) if report is not None else None
            label = _short_pub(dict(ep.get("qos") or {})) if ep else (
                "rospy (no micros_rt QoS)" if report is not None and report.kind == MICROS_RT else "stock")
            for way in carriage({pub: report} if report is not None else {}, t):
                label += f"\n{way['kind']} {way['direction']}"
            marking = relay_marking(report, t, publisher=True) if report is not None else None
            if marking is not None:
                label += f"\nrelayed in from graph {marking['origin']}"
            lines.append(f"  {_q('n:' + pub)} -> {_q('t:' + t)} [label={_q(label)}, color={_q(OTHER_COLOUR)}];")
        linked = set()
        for link in snap.links:
            if link.topic != t or link.subscriber not in shown:
                continue
            linked.add(link.subscriber)
            words = [f"{link.protocol} from {link.publisher}"]
            if link.subscriber_qos:
                words.append(_short_sub(link.subscriber_qos))
            if link.verdict and link.verdict != "accepted":
                words.append(f"DDS declined: {link.verdict}")
            words += [f"relayed out as {m['outside']}" for m in link.relayed if m["direction"] == "out"]
            colour = PROTOCOL_COLOURS.get(link.protocol, OTHER_COLOUR)
            lines.append(f"  {_q('t:' + t)} -> {_q('n:' + link.subscriber)} [label={_q(chr(10).join(words))}, "
                         f"color={_q(colour)}, fontcolor={_q(colour)}, penwidth=2];")
        for sub in sorted(set(snap.subscribers.get(t, [])) & shown - linked):
            lines.append(f"  {_q('t:' + t)} -> {_q('n:' + sub)} [label=\"no link\", style=dashed, "
                         f"color={_q(OTHER_COLOUR)}];")
    lines += ["  subgraph cluster_legend {", '    label="links"; fontsize=9; color="#cccccc";',
              '    node [shape=plaintext, fontsize=9];']
    carrier = "relay (between graphs)" if ros2 is None else "relay (between graphs, or ROS 1 and ROS 2)"
    legend = dict(PROTOCOL_COLOURS, **({carrier: RELAY_COLOUR} if relays else {}))
    for i, (proto, colour) in enumerate(legend.items()):
        lines.append(f'    "legend_{i}a" [label=""]; "legend_{i}b" [label={_q(proto)}, fontcolor={_q(colour)}];')
        lines.append(f'    "legend_{i}a" -> "legend_{i}b" [color={_q(colour)}, penwidth=2];')
    lines += ["  }", "}", ""]
    return "\n".join(lines)
