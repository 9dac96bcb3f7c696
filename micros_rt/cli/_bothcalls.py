"""Services and actions of ROS 1 and ROS 2 in one list, for ``micros-rt service list`` and ``micros-rt action list``.

- ROS 1 services: the master's ``getSystemState`` (name and server node); the type is asked of each server as
  ``rosservice type`` does (a TCPROS header with ``probe=1``).
- ROS 1 actions (actionlib): a node publishing ``<name>/status`` whose ``<name>/feedback`` is an ``*ActionFeedback``
  type is a server, a node publishing ``<name>/goal`` a client; ``pkg/FooActionFeedback`` is the action
  ``pkg/FooAction``.
- ROS 2 services and actions: DDS discovery (:mod:`._ddsgraph`): a reader of ``rq/<name>Request`` is a server, a
  writer a client (``pkg::srv::dds_::Foo_Request_`` is ``pkg/srv/Foo``); for an action the request topic of its
  ``_action/send_goal`` service (``pkg::action::dds_::Foo_SendGoal_Request_`` is ``pkg/action/Foo``).

A micros_rt node reaches ROS 2 with services and actions through its rclpy helper (a DDS participant of its own,
ROS 2 enclave ``/micros_rt``, node ``<node>_services``/``_actions``): its servers are shown as the micros_rt node's.
A ``micros-rt relay`` node says what its ``ros2:`` section carries (its ``microsRtInfo``), so a name it carries is
marked ``relay, to ROS 2`` or ``relay, from ROS 2`` on the side it serves.
"""

from __future__ import annotations

import concurrent.futures
import io
import re
import socket
import urllib.parse
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

from . import CommandError
from ._bothgraph import BOTH, ROS1, ROS2, Both, _is_hidden, _table, helper_owners
from ._bothinfo import ros2_entries
from ._graphinfo import Master, NodeReport, probe_all

__all__ = ["CallRow", "action_rows", "format_calls", "service_rows", "service_type"]

_SRV = re.compile(r"^(\w+)::srv::dds_::(\w+)_Request_$")
_ACTION = re.compile(r"^(\w+)::action::dds_::(\w+)_SendGoal_Request_$")
SEND_GOAL = "/_action/send_goal"
PROBE_TIMEOUT = 3.0


@dataclass
class CallRow:
    """A service or an action of either graph."""

    name: str
    side: str
    ros1_type: Optional[str]
    ros2_type: Optional[str]
    ros1_servers: List[str] = field(default_factory=list)
    ros2_servers: List[str] = field(default_factory=list)
    #: ROS 2 clients (writers of the request topic); ROS 1 action clients (publishers of ``<name>/goal``)
    ros1_clients: List[str] = field(default_factory=list)
    ros2_clients: List[str] = field(default_factory=list)
    #: what relays carry of it between ROS 1 and ROS 2, in words
    carried: List[str] = field(default_factory=list)

    def type_text(self) -> str:
        if self.ros1_type and self.ros2_type:
            return f"{self.ros1_type} (ROS 2: {self.ros2_type})"
        return self.ros1_type or self.ros2_type or "?"

    def to_dict(self) -> Dict[str, Any]:
        return dict(self.__dict__)


def service_type(uri: str, name: str, *, timeout: float = PROBE_TIMEOUT) -> Optional[str]:
    """A ROS 1 service's type, asked of its server (``rosrpc://host:port``) as ``rosservice type`` does; None when
    it does not answer."""
    from rosgraph.network import ROSHandshakeException, read_ros_handshake_header, write_ros_handshake_header

    parts = urllib.parse.urlparse(uri)
    if parts.scheme != "rosrpc" or not parts.hostname or not parts.port:
        return None
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            write_ros_handshake_header(sock, {"probe": "1", "md5sum": "*", "callerid": "/micros_rt_cli",
                                              "service": name})
            header = read_ros_handshake_header(sock, io.BytesIO(), 65536)
    except (OSError, ROSHandshakeException):
        return None
    found = header.get("type")
    return str(found) if found else None


def _ros2_ends(both: Both, dds_topic: str, owners: Mapping[str, str]) -> Tuple[List[str], List[str], Set[str]]:
    """(servers, clients, ROS 1 nodes behind helpers among them) of a request topic, by node name."""
    names = both.dds.owners()
    servers: List[str] = []
    clients: List[str] = []
    helped: Set[str] = set()
    for ep in both.dds.endpoints:
        if ep.topic != dds_topic or (ep.tag is not None and not both.ours(ep.tag)):
            continue
        node = names.get(ep.guid)
        name = node.full_name if node is not None else f"? (participant {ep.participant})"
        if ep.participant in both.dds.helpers and name in owners:
            helped.add(owners[name])
            name = f"{owners[name]} (its ROS 2 helper)"
        target = clients if ep.writer else servers
        if name not in target:
            target.append(name)
    return sorted(servers), sorted(clients), helped


def _side(ros1: bool, ros2: bool) -> str:
    return BOTH if ros1 and ros2 else ROS1 if ros1 else ROS2


def _mark_relays(rows: Sequence[CallRow], kind: str, master: Optional[Master], nodes: Set[str]) -> None:
    """Ask the nodes that may be relays (servers on both sides' names) what they carry, and mark the rows: the
    relay's servers as ``(relay)``, and ``carried`` in words."""
    if master is None or not nodes:
        return
    reports: Dict[str, NodeReport] = probe_all(master, nodes)
    by_name = {r.name: r for r in rows}
    for node, report in reports.items():
        for entry in ros2_entries(report):
            if entry.get("kind") != kind:
                continue
            export = entry.get("direction") == "export"
            ros1, ros2 = (entry.get("name"), entry.get("as")) if export else (entry.get("as"), entry.get("name"))
            words = (f"relay {node}: ROS 1 {ros1} -> ROS 2 {ros2}" if export else
                     f"relay {node}: ROS 2 {ros2} -> ROS 1 {ros1}")
            for name in {str(ros1), str(ros2)}:
                row = by_name.get(name)
                if row is None:
                    continue
                row.carried.append(words)
                for servers in (row.ros1_servers, row.ros2_servers):
                    servers[:] = [_relay_mark(s, node) for s in servers]


def _relay_mark(server: str, relay: str) -> str:
    """``/relay_robot`` -> ``/relay_robot (relay)``; ``/relay_robot (its ROS 2 helper)`` -> ``/relay_robot (relay,
    its ROS 2 helper)``."""
    if server == relay:
        return f"{relay} (relay)"
    if server.startswith(relay + " (") and not server.startswith(relay + " (relay"):
        return f"{relay} (relay, {server[len(relay) + 2:]}"
    return server


#: Every ROS 1 node's logger services, every ROS 2 node's parameter and type services (``-a`` lists them).
NODE_SERVICES = frozenset({"get_loggers", "set_logger_level", "describe_parameters", "get_parameter_types",
                           "get_parameters", "get_type_description", "list_parameters", "set_parameters",
                           "set_parameters_atomically"})


def _node_service(row: CallRow, nodes: Set[str]) -> bool:
    """Whether a row is a node's own service (``/talker/get_loggers``, ``/listener/set_parameters``): its name is
    a node's of either graph plus one of :data:`NODE_SERVICES`."""
    owner, _, leaf = row.name.rpartition("/")
    return leaf in NODE_SERVICES and owner in nodes


def service_rows(both: Both, master: Optional[Master], *, include_hidden: bool = False) -> List[CallRow]:
    """Every service of either graph, merged per name and sorted."""
    rows: Dict[str, CallRow] = {}
    owners = helper_owners(both)
    probe: Set[str] = set()
    types: Dict[str, Optional[str]] = {}
    names = sorted(both.ros1.services) if both.ros1.available else []
    if names and master is not None:
        def lookup(name: str) -> Optional[str]:
            try:
                return str(master.call("lookupService", name))
            except CommandError:  # gone since getSystemState
                return None

        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, min(16, len(names)))) as pool:
            uris = dict(zip(names, pool.map(lookup, names)))
            types = dict(zip(names, pool.map(lambda n: service_type(uris[n] or "", n) if uris[n] else None, names)))
    for name in names:
        rows[name] = CallRow(name, ROS1, types.get(name), None, sorted(both.ros1.services[name]))
    for ep in both.dds.endpoints:
        found = _SRV.match(ep.type_name)
        if not (ep.topic.startswith("rq/") and ep.topic.endswith("Request") and found):
            continue
        name = "/" + ep.topic[3:-len("Request")].lstrip("/")
        if _is_hidden(name) and not include_hidden and name not in rows:
            continue
        row = rows.setdefault(name, CallRow(name, ROS2, None, None))
        row.ros2_type = f"{found.group(1)}/srv/{found.group(2)}"
    for row in rows.values():
        row.ros2_servers, row.ros2_clients, helped = _ros2_ends(both, f"rq{row.name}Request", owners)
        row.side = _side(bool(row.ros1_servers), bool(row.ros2_servers or row.ros2_clients))
        if row.ros2_type is not None and row.ros1_type is not None:
            pkg, _, name = row.ros1_type.partition("/")
            if row.ros2_type == f"{pkg}/srv/{name}":
                row.ros2_type = None   # the ROS 1 type's mapping: shown once
        if row.side == BOTH:
            probe.update(row.ros1_servers)
            probe.update(helped)
    _mark_relays(list(rows.values()), "service", master, probe)
    nodes = both.ros1.nodes() | {n.full_name for n in both.dds.nodes}
    return [rows[n] for n in sorted(rows) if include_hidden or not _node_service(rows[n], nodes)]


def action_rows(both: Both, master: Optional[Master], *, include_hidden: bool = False) -> List[CallRow]:
    """Every action of either graph, merged per name and sorted."""
    rows: Dict[str, CallRow] = {}
    r1 = both.ros1
    for topic, type_name in r1.types.items():
        if not (topic.endswith("/feedback") and type_name.endswith("ActionFeedback")):
            continue
        name = topic[: -len("/feedback")]
        servers = sorted(r1.publishers.get(f"{name}/status", []))
        clients = sorted(r1.publishers.get(f"{name}/goal", []))
        if servers or clients:
            rows[name] = CallRow(name, ROS1, type_name[: -len("Feedback")], None, servers, ros1_clients=clients)
    owners = helper_owners(both)
    for ep in both.dds.endpoints:
        found = _ACTION.match(ep.type_name)
        if not (found and ep.topic.startswith("rq/") and ep.topic.endswith(SEND_GOAL + "Request")):
            continue
        name = "/" + ep.topic[3:-len(SEND_GOAL + "Request")].lstrip("/")
        if _is_hidden(name) and not include_hidden and name not in rows:
            continue
        row = rows.setdefault(name, CallRow(name, ROS2, None, None))
        row.ros2_type = f"{found.group(1)}/action/{found.group(2)}"
    probe: Set[str] = set()
    for row in rows.values():
        row.ros2_servers, row.ros2_clients, helped = _ros2_ends(both, f"rq{row.name}{SEND_GOAL}Request", owners)
        row.side = _side(bool(row.ros1_servers or row.ros1_clients), bool(row.ros2_servers or row.ros2_clients))
        if row.side == BOTH:
            probe.update(row.ros1_servers + row.ros1_clients)
            probe.update(helped)
    _mark_relays(list(rows.values()), "action", master, probe)
    return [rows[n] for n in sorted(rows)]


def _names(names: Sequence[str]) -> str:
    return ", ".join(names) or "-"


def format_calls(rows: Sequence[CallRow], what: str, *, verbose: bool = False) -> str:
    """``service list``/``action list``'s text: a table, or with ``verbose`` every entry's servers, clients and
    carriage."""
    if not rows:
        return f"no {what}s"
    if not verbose:
        return "\n".join(_table([what.upper(), "SIDE", "TYPE", "ROS 1 SERVER", "ROS 2 SERVER"], [
            [r.name, r.side, r.type_text(), _names(r.ros1_servers), _names(r.ros2_servers)] for r in rows]))
    lines = []
    for r in rows:
        lines.append(f"{r.name}  [{r.side}]  {r.type_text()}")
        lines.append(f"  {'ROS 1 servers:':<16} {_names(r.ros1_servers)}")
        if what == "action":
            lines.append(f"  {'ROS 1 clients:':<16} {_names(r.ros1_clients)}")
        lines.append(f"  {'ROS 2 servers:':<16} {_names(r.ros2_servers)}")
        lines.append(f"  {'ROS 2 clients:':<16} {_names(r.ros2_clients)}")
        lines += [f"  carried by {c}" for c in r.carried]
    return "\n".join(lines)


def list_main(prog: str, what: str, argv: List[str]) -> int:
    """``micros-rt service list`` / ``micros-rt action list`` (``what``: service or action)."""
    import json
    import sys

    from ._args import ArgumentParser
    from ._bothgraph import collect, sources
    from ._ddsgraph import DEFAULT_WAIT, NAMES_WAIT

    parser = ArgumentParser(
        prog=prog, usage="%(prog)s [-v] [--json] [--wait SEC] [-a]",
        description=f"List the {what}s of the ROS 1 master (ROS_MASTER_URI) and of ROS 2 (DDS discovery on "
                    f"ROS_DOMAIN_ID for --wait seconds) together, merged per name, with their types and servers. "
                    f"SIDE: ROS 1, ROS 2, or ROS 1+2 (served on both: a micros_rt node through its ROS 2 helper, or "
                    f"a relay carrying it). When one side cannot be read, the other is listed with a note on stderr.")
    parser.add_argument("-v", "--verbose", action="store_true", help="print each one's servers, clients and relays")
    parser.add_argument("--json", action="store_true", help="print JSON (for scripts) instead of text")
    parser.add_argument("--wait", type=float, default=DEFAULT_WAIT, metavar="SEC",
                        help=f"seconds of DDS discovery (default {DEFAULT_WAIT:g}); naming ROS 2 nodes takes up to "
                             f"{NAMES_WAIT:g} s more")
    parser.add_argument("-a", "--all", action="store_true",
                        help="also hidden ROS 2 names (a part starting with '_'), as ros2 ... list -a")
    args = parser.parse_args(argv)
    both = collect(args.wait)
    master = Master(both.ros1.uri) if both.ros1.available else None
    rows = (service_rows if what == "service" else action_rows)(both, master, include_hidden=args.all)
    if args.json:
        print(json.dumps({**sources(both), f"{what}s": [r.to_dict() for r in rows]}, indent=2))
    else:
        print(format_calls(rows, what, verbose=args.verbose))
        for note in both.notes():
            print(f"{prog}: note: {note}", file=sys.stderr)
    return 0
