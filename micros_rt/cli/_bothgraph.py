"""ROS 1 and ROS 2 in one list: the master's topics and nodes joined with what DDS discovery shows
(:mod:`._ddsgraph`), for ``micros-rt topic list`` and ``micros-rt node list``.

Which side an entry is on (the ``SIDE`` column):

- ``ROS 1``: only the ROS 1 master has it; ROS 2 nodes do not see it (a stock ROS 1 node, or a micros_rt node
  with ROS 2 visibility off or without DDS).
- ``ROS 2``: only DDS discovery has it, from endpoints that are not micros_rt's (ROS 2 nodes).
- ``ROS 1+2``: both graphs have it. A micros_rt node is one: registered with the master and a ROS 2 node on
  DDS (its endpoints carry micros_rt's tag, and it announces itself on ``ros_discovery_info``). A topic is
  when its name is in the master and on DDS: a micros_rt node's endpoint of it (so ROS 2 nodes see it), or
  a ROS 2 node's.

A micros_rt node and its endpoints are counted once, on the ROS 1 side; the ROS 2 counts are ROS 2 nodes'.
micros_rt endpoints of *other* ROS 1 graphs on the same DDS domain (another master's nodes, relays' outside
topics of other graphs) are left out and counted in a note.
"""

from __future__ import annotations

import concurrent.futures
import functools
import os
import socket
import urllib.parse
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

from . import CommandError
from ._ddsgraph import DdsView, Ros2Node, discover, ros2_type_name
from ._graphinfo import MICROS_RT, Master, probe_node

__all__ = ["Both", "NodeRow", "TopicRow", "collect", "format_nodes", "format_topics", "helper_owners", "node_rows",
           "topic_rows"]

ROS1, ROS2, BOTH = "ROS 1", "ROS 2", "ROS 1+2"
DDS_TOPIC_PREFIX = "rt/"


@dataclass
class Ros1View:
    """The master's answers, or ``note`` saying why there are none."""

    available: bool
    note: str = ""
    uri: str = ""
    run_id: str = ""
    publishers: Dict[str, List[str]] = field(default_factory=dict)
    subscribers: Dict[str, List[str]] = field(default_factory=dict)
    services: Dict[str, List[str]] = field(default_factory=dict)
    types: Dict[str, str] = field(default_factory=dict)

    def nodes(self) -> Set[str]:
        return {n for table in (self.publishers, self.subscribers, self.services) for ns in table.values() for n in ns}


@dataclass
class Both:
    ros1: Ros1View
    dds: DdsView

    def notes(self) -> List[str]:
        out = []
        if not self.ros1.available:
            out.append(f"ROS 1 side not listed: {self.ros1.note}")
        if not self.dds.available:
            out.append(f"ROS 2 side not listed: {self.dds.note}")
        if self.dds.unnamed:
            out.append(f"the ros_discovery_info of {len(self.dds.unnamed)} DDS participants (what names their ROS 2 "
                       f"nodes) did not come within {self.dds.wait:g} s: their nodes are missing and their endpoints "
                       f"unnamed; try a longer --wait")
        others = [e for e in self.dds.endpoints if e.tag is not None and not self.ours(e.tag)]
        if others:
            graphs = sorted({str(e.tag.get("graph", "?")).partition("@")[2] or "?" for e in others if e.tag})
            out.append(f"{len(others)} DDS endpoints of micros_rt nodes of other ROS 1 graphs on DDS domain "
                       f"{self.dds.domain} are not listed (masters {', '.join(graphs)})")
        return out

    def ours(self, tag: Mapping[str, str]) -> bool:
        """Whether a micros_rt tag names a node of this master's graph (its ``run_id``, or the URI when a node
        could not read it)."""
        if not self.ros1.available:
            return True  # nothing to tell graphs apart by: every micros_rt endpoint is taken as this graph's
        run_id, _, uri = str(tag.get("graph", "")).partition("@")
        if run_id and run_id != "norunid":
            return run_id == self.ros1.run_id
        return _same_master(uri, self.ros1.uri)


@functools.lru_cache(maxsize=64)
def _where(uri: str) -> Tuple[str, Optional[int]]:
    parts = urllib.parse.urlparse(uri.strip())
    host = parts.hostname or ""
    try:
        return socket.gethostbyname(host), parts.port
    except OSError:
        return host, parts.port


def _same_master(a: str, b: str) -> bool:
    """Whether two master URIs name one master (``localhost`` and ``127.0.0.1`` alike).

    >>> _same_master("http://127.0.0.1:11311/", "http://127.0.0.1:11311")
    True
    """
    try:
        return _where(a) == _where(b)
    except ValueError:  # a port that is no number
        return a.rstrip("/") == b.rstrip("/")


def _ros1(master: Master) -> Ros1View:
    try:
        pubs, subs, srvs = master.call("getSystemState")
        types = {t: ty for t, ty in master.call("getTopicTypes")}
    except CommandError as exc:
        return Ros1View(False, str(exc), uri=master.uri)
    try:
        run_id = str(master.call("getParam", "/run_id"))
    except CommandError:
        run_id = ""  # a master without /run_id (not roscore): micros_rt tags then say "norunid"
    return Ros1View(True, uri=master.uri, run_id=run_id, publishers={t: list(n) for t, n in pubs},
                    subscribers={t: list(n) for t, n in subs}, services={s: list(n) for s, n in srvs}, types=types)


def collect(wait: float, env: Mapping[str, str] = os.environ, *, names: bool = True) -> Both:
    """The master's view and ``wait`` seconds of DDS discovery (:func:`._ddsgraph.discover`; with ``names``,
    until ROS 2 nodes are named), side by side (both asked at once)."""
    if wait < 0:
        raise CommandError("--wait must not be negative", code=2)
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        ros1 = pool.submit(_ros1, Master())
        dds = discover(wait, env, names=names)
        both = Both(ros1.result(), dds)
    if not both.ros1.available and not both.dds.available:
        raise CommandError(f"neither graph can be read: {both.ros1.note}; and {both.dds.note}")
    return both


def helper_owners(both: Both) -> Dict[str, str]:
    """ROS 2 node name of a micros_rt node's rclpy helper (``/relay_robot_services``, ``/relay_robot_actions``) ->
    the ROS 1 node it serves for (``/relay_robot``)."""
    from ..services.gateway import _ros2_node_name

    owners = {}
    for node in both.ros1.nodes():
        stem = _ros2_node_name(node)[: -len("_services")]
        for suffix in ("_services", "_actions"):
            owners[f"/{stem}{suffix}"] = node
    return owners


# --------------------------------------------------------------------------- topics

@dataclass
class TopicRow:
    topic: str
    side: str
    ros1_type: Optional[str]
    ros2_types: List[str]
    ros1_publishers: List[str]
    ros1_subscribers: List[str]
    #: this graph's micros_rt nodes with a DDS writer / reader of the topic (what makes them ROS 2 visible)
    dds_publishers: List[str]
    dds_subscribers: List[str]
    #: ROS 2 nodes' writers / readers, one entry per endpoint (its node's name from ros_discovery_info, else
    #: "? (participant GUID)")
    ros2_publishers: List[str]
    ros2_subscribers: List[str]

    def type_text(self) -> str:
        if self.ros1_type is None:
            return ", ".join(self.ros2_types) or "?"
        if not self.ros2_types:
            return self.ros1_type
        pkg, _, name = self.ros1_type.partition("/")
        different = [t for t in self.ros2_types if t != f"{pkg}/msg/{name}"]
        return self.ros1_type + (f" (ROS 2: {', '.join(different)})" if different else "")

    def to_dict(self) -> Dict[str, Any]:
        return dict(self.__dict__)


def _is_hidden(name: str) -> bool:
    """ROS 2 hides names with a part starting with '_' (``/_action/...``) unless asked (ros2 topic list -a)."""
    return any(part.startswith("_") for part in name.split("/"))


def _endpoint_owner(both: Both) -> Dict[str, str]:
    """Endpoint GUID -> the ROS 2 node that announced it."""
    owners = {}
    for node in both.dds.nodes:
        for guid in node.readers + node.writers:
            owners[guid] = node.full_name
    return owners


def topic_rows(both: Both, *, include_hidden: bool = False) -> List[TopicRow]:
    """Every topic of either graph, merged per name and sorted."""
    r1 = both.ros1
    owners = _endpoint_owner(both)
    rows: Dict[str, TopicRow] = {}

    def row(name: str) -> TopicRow:
        if name not in rows:
            rows[name] = TopicRow(name, ROS1, r1.types.get(name), [], sorted(r1.publishers.get(name, [])),
                                  sorted(r1.subscribers.get(name, [])), [], [], [], [])
        return rows[name]

    for name in set(r1.types) | set(r1.publishers) | set(r1.subscribers):
        row(name)
    for ep in both.dds.endpoints:
        if not ep.topic.startswith(DDS_TOPIC_PREFIX):
            continue  # ROS 2 services (rq/, rr/), ros_discovery_info, plain DDS topics
        name = "/" + ep.topic[len(DDS_TOPIC_PREFIX):]
        if ep.tag is not None:
            if not both.ours(ep.tag):
                continue
            r = row(name)
            node = ep.tag.get("node", "?")
            target = r.dds_publishers if ep.writer else r.dds_subscribers
        else:
            if _is_hidden(name) and not include_hidden and name not in r1.types:
                continue
            r = row(name)
            node = owners.get(ep.guid) or f"? (participant {ep.participant})"
            target = r.ros2_publishers if ep.writer else r.ros2_subscribers
            if ros2_type_name(ep.type_name) not in r.ros2_types:
                r.ros2_types.append(ros2_type_name(ep.type_name))
        if ep.tag is None or node not in target:  # ROS 2: each endpoint, as ros2 topic info counts them
            target.append(node)
    for r in rows.values():
        in_master = r.topic in r1.types or bool(r.ros1_publishers or r.ros1_subscribers)
        on_dds = bool(r.dds_publishers or r.dds_subscribers or r.ros2_publishers or r.ros2_subscribers)
        r.side = BOTH if (in_master or r.dds_publishers or r.dds_subscribers) and on_dds else ROS1 if in_master \
            else ROS2
        for names in (r.dds_publishers, r.dds_subscribers, r.ros2_publishers, r.ros2_subscribers, r.ros2_types):
            names.sort()
    return [rows[name] for name in sorted(rows)]


def _count(pubs: Sequence[str], subs: Sequence[str]) -> str:
    return f"{len(pubs)}/{len(subs)}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> List[str]:
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
    return ["  ".join(str(x).ljust(w) for x, w in zip(r, widths)).rstrip() for r in [header, *rows]]


def _names(endpoints: Sequence[str]) -> str:
    """Endpoints' node names, each once (``x2`` when a node has more than one)."""
    counts: Dict[str, int] = {}
    for name in endpoints:
        counts[name] = counts.get(name, 0) + 1
    return ", ".join(n + (f" x{c}" if c > 1 else "") for n, c in counts.items()) or "none"


def format_topics(rows: Sequence[TopicRow], *, verbose: bool = False, ros1: bool = True, ros2: bool = True) -> str:
    """``topic list``'s text: a table, or with ``verbose`` every topic's nodes per side; a side that could not be
    read (``ros1``/``ros2`` False) has ``?`` for counts."""
    if not rows:
        return "no topics"
    if not verbose:
        table = [[r.topic, r.side, r.type_text(),
                  "?" if not ros1 else _count(r.ros1_publishers, r.ros1_subscribers) if r.side != ROS2 else "-",
                  "?" if not ros2 else _count(r.ros2_publishers, r.ros2_subscribers) if r.side != ROS1 else "-"]
                 for r in rows]
        return "\n".join(_table(["TOPIC", "SIDE", "TYPE", "ROS 1 PUB/SUB", "ROS 2 PUB/SUB"], table))
    lines: List[str] = []
    for r in rows:
        lines.append(f"{r.topic}  [{r.side}]  {r.type_text()}")
        for title, names, on_dds in (("ROS 1 publishers", r.ros1_publishers, r.dds_publishers),
                                     ("ROS 1 subscribers", r.ros1_subscribers, r.dds_subscribers)):
            shown = [f"{n} (micros_rt, also on DDS)" if n in on_dds else n for n in names]
            shown += [f"{n} (micros_rt, on DDS only)" for n in on_dds if n not in names]
            if r.side != ROS2 or shown:
                lines.append(f"  {title + ':':<20} {', '.join(shown) or 'none'}")
        if r.side != ROS1:
            lines.append(f"  {'ROS 2 publishers:':<20} {_names(r.ros2_publishers)}")
            lines.append(f"  {'ROS 2 subscribers:':<20} {_names(r.ros2_subscribers)}")
        if r.side == BOTH and not (r.dds_publishers or r.dds_subscribers):
            lines.append("  note: none of its ROS 1 endpoints is on DDS: its ROS 1 and ROS 2 nodes do not exchange "
                         "messages (a micros_rt node on the ROS 1 side would carry them)")
    return "\n".join(lines)


# --------------------------------------------------------------------------- nodes

@dataclass
class NodeRow:
    node: str
    side: str
    #: micros_rt, stock or unreachable (``-v`` only: asked of the node), None for ROS 2 nodes
    ros1_kind: Optional[str] = None
    participants: List[str] = field(default_factory=list)
    readers: int = 0
    writers: int = 0
    detail: str = ""

    def to_dict(self) -> Dict[str, Any]:
        return dict(self.__dict__)


def _micros_rt_node(node: Ros2Node, tags: Mapping[str, Optional[Dict[str, str]]], by_participant: Mapping[
        str, List[Optional[Dict[str, str]]]]) -> Tuple[Optional[bool], Optional[Dict[str, str]]]:
    """(is it a micros_rt node, one of its tags) from its endpoints' tags, else its participant's endpoints';
    (None, None) when discovery has shown none of them yet."""
    own = [tags[g] for g in node.readers + node.writers if g in tags]
    for known in (own, by_participant.get(node.participant, [])):
        tagged = [t for t in known if t is not None]
        if tagged:
            return True, tagged[0]
        if known:
            return False, None  # endpoints known, none tagged: a ROS 2 node
    return None, None


def node_rows(both: Both, *, include_hidden: bool = False, probe: bool = False) -> List[NodeRow]:
    """Every node of either graph, merged per name and sorted; ``probe`` asks each ROS 1 node whether it is a
    micros_rt node (``microsRtInfo``)."""
    r1 = both.ros1
    tags: Dict[str, Optional[Dict[str, str]]] = {e.guid: e.tag for e in both.dds.endpoints}
    by_participant: Dict[str, List[Optional[Dict[str, str]]]] = {}
    for e in both.dds.endpoints:
        by_participant.setdefault(e.participant, []).append(e.tag)
    master_nodes = r1.nodes()
    rows: Dict[Tuple[str, str], NodeRow] = {}
    for name in master_nodes:
        rows[(name, ROS1)] = NodeRow(name, ROS1)
    for node in both.dds.nodes:
        name = node.full_name
        is_mrt, tag = _micros_rt_node(node, tags, by_participant)
        if is_mrt and tag is not None and not both.ours(tag):
            continue  # another ROS 1 graph's micros_rt node (counted in the notes with its endpoints)
        if is_mrt or (is_mrt is None and name in master_nodes):
            key = (name, ROS1)  # this graph's micros_rt node: the master's entry is on both sides
            if key not in rows:
                rows[key] = NodeRow(name, ROS1)
            rows[key].side = BOTH
        else:
            if not include_hidden and node.name.startswith("_"):
                continue  # ros2 node list hides these (the ros2 daemon, ...) unless -a
            key = (name, ROS2)
            rows.setdefault(key, NodeRow(name, ROS2))
        r = rows[key]
        if node.participant not in r.participants:
            r.participants.append(node.participant)
        r.readers += len(node.readers)
        r.writers += len(node.writers)
    if probe and r1.available:
        names = sorted(name for (name, _side), r in rows.items() if r.side != ROS2)
        master = Master(r1.uri)
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, min(16, len(names)))) as pool:
            reports = dict(zip(names, pool.map(lambda n: probe_node(n, master.lookup_node(n)), names)))
        for (name, _side), r in rows.items():
            if name in reports and r.side != ROS2:
                r.ros1_kind = reports[name].kind
    helped = helper_owners(both)
    for r in rows.values():
        r.detail = _node_detail(r)
        if r.side == ROS2 and r.participants and set(r.participants) <= both.dds.helpers:
            owner = helped.get(r.node)
            r.detail = (f"micros_rt's rclpy helper{' of ' + owner if owner else ''}: its services and actions toward "
                        f"ROS 2 (a DDS participant of its own, ROS 2 enclave /micros_rt)")
    return sorted(rows.values(), key=lambda r: (r.node, r.side))


def _n(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _node_detail(r: NodeRow) -> str:
    dds = f"{_n(r.writers, 'writer')}, {_n(r.readers, 'reader')} on DDS"
    if r.side == BOTH:
        return f"micros_rt node: in the ROS 1 master and a ROS 2 node ({dds})"
    if r.side == ROS2:
        return f"ROS 2 node ({dds}, participant {', '.join(r.participants)})"
    if r.ros1_kind == MICROS_RT:
        return ("micros_rt node not announced to ROS 2 (ROS 2 visibility off, or auto with no ROS 2 node seen on the "
                "domain; DDS unavailable; or no topic yet)")
    if r.ros1_kind is None:
        return "ROS 1 node"
    return f"{r.ros1_kind} ROS 1 node" + ("" if r.ros1_kind == "unreachable" else " (TCPROS only, not on DDS)")


def format_nodes(rows: Sequence[NodeRow], *, verbose: bool = False) -> str:
    if not rows:
        return "no nodes"
    header = ["NODE", "SIDE"] + (["DETAIL"] if verbose else [])
    return "\n".join(_table(header, [[r.node, r.side] + ([r.detail] if verbose else []) for r in rows]))


def summary_lines(both: Both) -> List[str]:
    """Where each side came from (``-v``)."""
    r1, d = both.ros1, both.dds
    return [f"ROS 1: master {r1.uri}" if r1.available else f"ROS 1: unavailable ({r1.note})",
            f"ROS 2: DDS domain {d.domain}, {d.wait:g} s of discovery, {len(d.participants)} participants, "
            f"{len(d.endpoints)} readers and writers" if d.available else f"ROS 2: unavailable ({d.note})", ""]


def sources(both: Both) -> Dict[str, Any]:
    """The ``--json`` output's account of both sides."""
    r1, d = both.ros1, both.dds
    return {"ros1": {"available": r1.available, "master": r1.uri, "note": r1.note or None},
            "ros2": {"available": d.available, "domain": d.domain, "wait": d.wait, "note": d.note or None},
            "notes": both.notes()}


def list_main(prog: str, what: str, argv: List[str]) -> int:
    """``micros-rt topic list`` / ``micros-rt node list`` (``what``: topics or nodes)."""
    import json
    import sys

    from ._args import ArgumentParser
    from ._ddsgraph import DEFAULT_WAIT, NAMES_WAIT

    if what == "topics":
        sides = ("ROS 1 (in the master only: ROS 2 nodes do not see it), ROS 2 (on DDS only: ROS 2 nodes' topic), "
                 "ROS 1+2 (in both: a micros_rt node's endpoint is on DDS too, or ROS 1 and ROS 2 nodes share the "
                 "name). Counts are publishers/subscribers; a micros_rt node is counted once, under ROS 1")
    else:
        sides = ("ROS 1 (in the master only: a stock node, or a micros_rt node with ROS 2 visibility off), ROS 2 "
                 "(a ROS 2 node, named by its ros_discovery_info), ROS 1+2 (a micros_rt node: in the master and "
                 "announced to ROS 2)")
    parser = ArgumentParser(
        prog=prog, usage="%(prog)s [-v] [--json] [--wait SEC] [-a]",
        description=f"List the {what} of the ROS 1 master (ROS_MASTER_URI) and of ROS 2 (DDS discovery on "
                    f"ROS_DOMAIN_ID, with micros_rt's Cyclone configuration, for --wait seconds) together, merged "
                    f"per name. SIDE: {sides}. When one side cannot be read, the other is listed with a note on "
                    f"stderr.")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="print each topic's nodes per side" if what == "topics" else
                        "say what each node is (asks each ROS 1 node whether it is a micros_rt node)")
    parser.add_argument("--json", action="store_true", help="print JSON (for scripts) instead of text")
    parser.add_argument("--wait", type=float, default=DEFAULT_WAIT, metavar="SEC",
                        help=f"seconds of DDS discovery before listing (default {DEFAULT_WAIT:g}); naming ROS 2 nodes "
                             f"(node list, -v, --json) takes up to {NAMES_WAIT:g} s more, while a participant's "
                             f"ros_discovery_info has not come")
    parser.add_argument("-a", "--all", action="store_true",
                        help="also hidden ROS 2 names (a part starting with '_'), as ros2 ... list -a")
    args = parser.parse_args(argv)
    both = collect(args.wait, names=what == "nodes" or args.verbose or args.json)
    if what == "topics":
        rows: Sequence[Any] = topic_rows(both, include_hidden=args.all)
        text = format_topics(rows, verbose=args.verbose, ros1=both.ros1.available, ros2=both.dds.available)
    else:
        rows = node_rows(both, include_hidden=args.all, probe=args.verbose)
        text = format_nodes(rows, verbose=args.verbose)
    if args.json:
        print(json.dumps({**sources(both), what: [r.to_dict() for r in rows]}, indent=2))
    else:
        print("\n".join(summary_lines(both)) + text if args.verbose else text)
        for note in both.notes():
            print(f"{prog}: note: {note}", file=sys.stderr)
    return 0

