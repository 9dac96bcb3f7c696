"""Helpers for the mcu-bridge integration tests: build the C stand-in, pick ports, start the bridge.

No micros_rt import: like tests/harness.py, this must work even when the library is broken.
"""

from __future__ import annotations

import socket
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List

import harness

STANDIN_SOURCE = harness.PEERS_DIR / "mcu_standin.c"
ROS_SERVICE_PEER = harness.PEERS_DIR / "mcu_ros_service.py"
MRT_PEER = harness.PEERS_DIR / "mrt_peer.py"
BOARD_ADDRESS = "127.0.0.2"
BRIDGE_ADDRESS = "127.0.0.1"


def build_standin(directory: Path) -> Path:
    """Compile tests/peers/mcu_standin.c with gcc against Debian's libmsgpack-dev; the binary's path."""
    binary = directory / "mcu_standin"
    cp = subprocess.run(["gcc", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(binary), str(STANDIN_SOURCE),
                         "-lmsgpackc", "-lm"], capture_output=True, text=True, timeout=120)
    if cp.returncode != 0:
        raise AssertionError(f"gcc failed ({cp.returncode}):\n{cp.stderr}")
    return binary


def free_port(address: str, kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind((address, 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class Ports:
    """The four ports of one link (each test its own)."""

    board_topic: int
    board_service: int
    bridge_topic: int
    bridge_service: int
    board: str = BOARD_ADDRESS
    bridge: str = BRIDGE_ADDRESS

    @classmethod
    def pick(cls, board: str = BOARD_ADDRESS, bridge: str = BRIDGE_ADDRESS) -> "Ports":
        return cls(free_port(board, socket.SOCK_DGRAM), free_port(board, socket.SOCK_STREAM),
                   free_port(bridge, socket.SOCK_DGRAM), free_port(bridge, socket.SOCK_STREAM), board, bridge)

    def yaml(self) -> str:
        return (f"microcontroller: {{address: {self.board}, topic_port: {self.board_topic}, "
                f"service_port: {self.board_service}}}\n"
                f"bind: {{address: {self.bridge}, topic_port: {self.bridge_topic}, "
                f"service_port: {self.bridge_service}}}\n")

    def standin_args(self) -> List[str]:
        return ["--address", self.board, "--topic-port", str(self.board_topic), "--service-port",
                str(self.board_service), "--bridge", self.bridge, "--bridge-topic-port", str(self.bridge_topic),
                "--bridge-service-port", str(self.bridge_service)]


def write_config(directory: Path, ports: Ports, body: str, name: str = "mcu.yaml") -> Path:
    path = directory / name
    path.write_text(ports.yaml() + body)
    return path


def bridge_argv(config: Path, node_name: str) -> List[str]:
    """``python -m micros_rt.bridges.mcu --config ... --json`` under the project's venv."""
    return [harness.MICROS_RT_PYTHON, "-m", "micros_rt.bridges.mcu", "--config", str(config), "--name", node_name, "--json"]


def standin_argv(binary: Path, ports: Ports, *extra: Any) -> List[str]:
    """The C board with the link's ports and ``extra`` options."""
    return [str(binary), *ports.standin_args(), *[str(a) for a in extra]]


def mrt_peer_argv(*args: Any) -> List[str]:
    return [harness.MICROS_RT_PYTHON, str(MRT_PEER), *[str(a) for a in args]]


def latest_stats(bridge: harness.Peer) -> Dict[str, Any]:
    events = bridge.events("stats")
    return events[-1] if events else {}


def wait_stats(bridge: harness.Peer, check: Callable[[Dict[str, Any]], bool], timeout: float) -> Dict[str, Any]:
    """The first ``stats`` event (JSON line from ``--json``) for which ``check`` holds."""
    return bridge.wait_for(lambda e: e.get("event") == "stats" and check(e), timeout)


def rosservice(master: harness.RosMaster, *args: str, timeout: float = 30.0) -> "subprocess.CompletedProcess[str]":
    """Stock ``rosservice ARGS`` against ``master`` (not checked: the caller looks at the exit code)."""
    try:
        return subprocess.run([harness.STOCK_PYTHON, "/usr/bin/rosservice", *args], env=master.env,
                              stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"rosservice {' '.join(args)} timed out after {timeout} s: {exc.stdout!r}") from None


def connections(master: harness.RosMaster, node: str, topic: str) -> int:
    """How many links node ``node`` has on ``topic`` now (getBusInfo: DDS and TCPROS alike)."""
    try:
        info = harness.node_call(harness.lookup_node(master, node), "getBusInfo")
    except (AssertionError, OSError):
        return 0
    return sum(1 for c in info if c[4] == topic)
