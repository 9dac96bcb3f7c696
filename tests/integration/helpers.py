"""Small helpers shared by the integration tests (peer command lines, socket inspection, C++ peers' builds)."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import urllib.parse
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Set, Tuple

import harness

MRT_PEER = str(harness.PEERS_DIR / "mrt_peer.py")
ROS1_SERVICE_PEER = str(harness.PEERS_DIR / "ros1_service_peer.py")
ROS2_SERVICE_PEER = str(harness.PEERS_DIR / "ros2_service_peer.py")
CLI = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")


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


def ros1_service_peer(impl: str, mode: str, spec: List[Dict[str, Any]], *extra: str) -> List[str]:
    """Command line of tests/peers/ros1_service_peer.py: ``impl`` "rospy" (stock) or "micros_rt", ``mode`` "serve"
    (``spec``: the services) or "call" (``spec``: the plan); ``extra``: the mode's options (``--quiet``)."""
    python = harness.MICROS_RT_PYTHON if impl == "micros_rt" else harness.STOCK_PYTHON
    key = "--services" if mode == "serve" else "--plan"
    return [python, ROS1_SERVICE_PEER, "--impl", impl, mode, key, json.dumps(spec), *extra]


def ros2_service_peer(mode: str, spec: List[Dict[str, Any]], *extra: str) -> List[str]:
    """Command line of tests/peers/ros2_service_peer.py (rclpy, .venv-ros2), as :func:`ros1_service_peer`."""
    key = "--services" if mode == "serve" else "--plan"
    return [harness.ROS2_PYTHON, ROS2_SERVICE_PEER, mode, key, json.dumps(spec), *extra]


def relay_argv(config: Path, *extra: str, stats_period: float = 0.3, poll_period: float = 0.3) -> List[str]:
    """Command line of ``micros-rt relay --config CONFIG --json`` with the short periods tests want."""
    return [CLI, "relay", "--config", str(config), "--json", "--stats-period", str(stats_period),
            "--poll-period", str(poll_period), *extra]


class CxxPeerBuild:
    """A C++ peer (tests/peers/NAME.cpp) compiled with g++ against Debian's ROS 1 ``-dev`` packages, found with
    ``pkg-config``; the compiler starts at once and :meth:`binary` waits for it, so that a test's other processes
    start meanwhile. A failed build is an AssertionError with the compiler's message (a failed test, never a skip).

    >>> build = CxxPeerBuild(harness.PEERS_DIR / "roscpp_setbool.cpp", tmp, ("roscpp",))  # doctest: +SKIP
    >>> spawn([build.binary(), "server", "/set_bool"])                                   # doctest: +SKIP
    """

    def __init__(self, source: Path, directory: Path, packages: Sequence[str]) -> None:
        self.source = source
        self.path = directory / source.stem
        self._error: Optional[str] = None
        self._proc: Optional["subprocess.Popen[str]"] = None
        self.argv: List[str] = []
        try:
            flags = subprocess.run(["pkg-config", "--cflags", "--libs", *packages], capture_output=True, text=True,
                                   timeout=30)
            if flags.returncode != 0:
                self._error = (f"pkg-config {' '.join(packages)} failed ({flags.returncode}): {flags.stderr.strip()}"
                               f"; scripts/setup.sh installs their Debian -dev packages")
                return
            # -O0: the build's time counts against the suite's; the peers measure the ROS stack, not their own code
            self.argv = ["g++", "-O0", "-Wall", "-Wextra", "-Werror", "-o", str(self.path), str(source),
                         *shlex.split(flags.stdout)]
            self._proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                          stderr=subprocess.STDOUT, text=True)
        except (OSError, subprocess.TimeoutExpired) as exc:  # no pkg-config or g++: scripts/setup.sh installs them
            self._error = f"{type(exc).__name__}: {exc}; scripts/setup.sh installs g++ and pkgconf"

    def binary(self, timeout: float = 300.0) -> str:
        """The built program's path, once g++ has finished; AssertionError with its output when it failed."""
        proc = self._proc
        if proc is not None and self._error is None and proc.returncode is None:
            try:
                output, _ = proc.communicate(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                output, _ = proc.communicate()
                self._error = f"g++ did not finish within {timeout:g} s: {' '.join(self.argv)}\n{output}"
            else:
                if proc.returncode != 0:
                    self._error = f"g++ failed ({proc.returncode}): {' '.join(self.argv)}\n{output}"
        if self._error is not None:
            raise AssertionError(f"cannot build {self.source.name}: {self._error}")
        return str(self.path)

    def close(self) -> None:
        """Stop a build still running (harmless twice)."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.communicate()


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
