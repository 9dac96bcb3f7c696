"""One ROS 2 helper per host (issue 42): micros_rt processes that offer services to ROS 2 share the host's helper
process, one DDS participant, each with its own rclpy node in it, so ROS 2's graph still shows a node per process.
A process that dies takes only its node; the helper exits once the last process left. Defaults (ROS 2 visibility
``auto``): an rclpy client on the domain first, so the servers start their ROS 2 side at once."""

from __future__ import annotations

import json
import os
import re
import signal
from pathlib import Path
from typing import Any, Dict, List

import pytest

import harness
from micros_rt.services import gateway

pytestmark = pytest.mark.integration

T = 40.0
#: a server's node in the helper (the server's own node may be in ROS 2's graph as well, by the host's presence)
HELPER_NODE = r"^mrt_service_server_.*_services$"
P = f"/hh{os.getpid()}"


def helpers_at(address: str) -> List[int]:
    """The live ROS 2 helper processes of ``address`` (its first argument)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                argv = (entry / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if any(a.endswith(b"ros2_helper.py") for a in argv) and address.encode() in argv and alive(int(entry.name)):
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_the_processes_of_a_host_share_one_ros2_helper_each_with_its_node(ros_master: harness.RosMaster,
                                                                           spawn: harness.Spawner) -> None:
    env = dict(ros_master.env)
    names = [f"{P}/a", f"{P}/b", f"{P}/c"]

    def client(label: str, services: List[str]) -> harness.Peer:
        return spawn([harness.ROS2_PYTHON, str(harness.PEERS_DIR / "ros2_service_peer.py"), "call", "--plan",
                      json.dumps([{"label": n, "name": n, "type": "std_srvs/srv/Trigger", "count": 3, "timeout": 10,
                                   "wait": T} for n in services])], env=env, name=f"rclpy_client_{label}")

    def node_count(n: int) -> Dict[str, Any]:
        info = spawn([harness.ROS2_PYTHON, str(harness.PEERS_DIR / "ros2_peer.py"), "info", "--topic", f"{P}/none",
                      "--wait", str(T), "--node-count", f"{HELPER_NODE}:{n}"], env=env, name="rclpy_info")
        return dict(info.wait_for("info", T + 20))

    first = client("first", names)    # a ROS 2 node on the domain: the servers start their ROS 2 side at once
    servers = [spawn([harness.MICROS_RT_PYTHON, str(harness.PEERS_DIR / "ros1_service_peer.py"), "--impl",
                      "micros_rt", "serve", "--services", json.dumps([{"name": n, "type": "std_srvs/Trigger"}]),
                      "--seconds", "120"], env=env, name=f"mrt_server_{i}") for i, n in enumerate(names)]
    for server in servers:
        server.wait_for("ready", T)
    for n in names:
        summary = [e for e in first.wait_for_count("summary", len(names), 2 * T) if e["label"] == n][0]
        assert summary["ok"] == 3, summary
    # one helper for the three (a second one started in a race exits at once: it cannot bind the address); it may
    # be one an earlier test's processes started, on this run's domain, and not yet gone
    address = gateway.helper_address(str(gateway.ros2_python(env)), env)
    harness.wait_until(lambda: len(helpers_at(address)) == 1, T, message=f"one helper: {helpers_at(address)}")
    helper = helpers_at(address)[0]
    # ROS 2's graph: a node per process, all in the helper's one participant
    nodes = [name for _ns, name in node_count(3)["nodes"] if re.search(HELPER_NODE, name)]
    assert len(nodes) == 3, nodes

    # a process killed: its node goes, the others' services still answer through the same helper
    victim = servers[0]
    victim.proc.send_signal(signal.SIGKILL)
    victim.proc.wait(timeout=10)
    assert len([name for _ns, name in node_count(2)["nodes"] if re.search(HELPER_NODE, name)]) == 2
    rest = [n for s, n in zip(servers, names) if s is not victim]
    second = client("second", rest)
    for n in rest:
        summary = [e for e in second.wait_for_count("summary", len(rest), 2 * T) if e["label"] == n][0]
        assert summary["ok"] == 3, summary
    assert helpers_at(address) == [helper]

    # one more leaves: the helper stays for the last one (whichever process started it), then exits after it
    servers[1].stop()
    third = client("third", [names[2]])
    assert third.wait_for("summary", 2 * T)["ok"] == 3
    assert helpers_at(address) == [helper]
    servers[2].stop()
    harness.wait_until(lambda: not alive(helper), T, message="the helper gone after the last process left")
