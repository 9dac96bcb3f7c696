"""Small helpers shared by the integration tests (peer command lines, socket inspection)."""

from __future__ import annotations

import json
import re
import subprocess
import urllib.parse
from typing import Any, Dict, List, Optional, Set, Tuple

import harness

MRT_PEER = str(harness.PEERS_DIR / "mrt_peer.py")


def mrt(mode: str, *args: Any, qos: Optional[Dict[str, Any]] = None) -> List[str]:
    """Command line of a micros_rt peer (project venv)."""
    argv = [harness.MICROS_RT_PYTHON, MRT_PEER, mode, *[str(a) for a in args]]
    if qos is not None:
        argv += ["--qos", json.dumps(qos)]
    return argv


def stock_talker(*args: Any) -> List[str]:
    return [harness.STOCK_PYTHON, str(harness.STOCK_TALKER), *[str(a) for a in args]]


def stock_listener(*args: Any) -> List[str]:
    return [harness.STOCK_PYTHON, str(harness.STOCK_LISTENER), *[str(a) for a in args]]


def received(peer: harness.Peer) -> List[Any]:
    return [e.get("data") for e in peer.events("recv")]


def transports(peer: harness.Peer) -> List[str]:
    return [e.get("transport", "") for e in peer.events("recv")]


def logs(peer: harness.Peer, level: str = "WARNING") -> List[str]:
    return [e["text"] for e in peer.events("log") if e.get("level") == level]


_SS_LINE = re.compile(r"(\S+):(\d+)\s+(\S+):(\d+)\s+users:\(\((.*)\)\)")


def tcp_links_between(pid_a: int, pid_b: int) -> List[Tuple[str, str]]:
    """Established TCP connections with one end in each process (from the kernel, via ss)."""
    out = subprocess.run(["ss", "-tnpH", "state", "established"], capture_output=True, text=True,
                         timeout=10).stdout
    owners: Dict[str, Set[int]] = {}
    sockets: List[Tuple[str, str, Set[int]]] = []
    for line in out.splitlines():
        m = _SS_LINE.search(line)
        if not m:
            continue
        local = f"{m.group(1)}:{m.group(2)}"
        peer = f"{m.group(3)}:{m.group(4)}"
        pids = {int(p) for p in re.findall(r"pid=(\d+)", m.group(5))}
        owners.setdefault(local, set()).update(pids)
        sockets.append((local, peer, pids))
    links = []
    for local, peer, pids in sockets:
        if pid_a in pids and pid_b in owners.get(peer, set()):
            links.append((local, peer))
    return links


def data_links_between(master: harness.RosMaster, a: Tuple[str, int], b: Tuple[str, int]) -> List[Tuple[str, str]]:
    """TCP connections between nodes ``a`` and ``b`` (name, pid), both directions, other than calls to either
    node's XML-RPC API (a requestTopic or a tool's query in flight is not a data link)."""
    api_ports = {urllib.parse.urlparse(harness.lookup_node(master, name)).port for name, _pid in (a, b)}
    links = tcp_links_between(a[1], b[1]) + tcp_links_between(b[1], a[1])
    return [(local, peer) for local, peer in links if int(peer.rsplit(":", 1)[1]) not in api_ports]


def bus_info(master: harness.RosMaster, node: str) -> List[List[Any]]:
    uri = harness.lookup_node(master, node)
    return list(harness.node_call(uri, "getBusInfo"))
