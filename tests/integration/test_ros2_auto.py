"""ROS 2 visibility ``auto``, the default: micros_rt nodes of one host make no DDS participant of their own while
nothing but micros_rt is on the DDS domain (one node, the host's watcher, has one with no topics); while ROS 2 is
there, the watcher is the host's one presence in ROS 2's graph (every node and endpoint, named as the node's), and a
node's topics become ROS 2 topics of its own once a ROS 2 endpoint is on one of them, whichever starts first; the
watcher's death hands the watch to another node.

The rest of the suite runs the defaults too (``auto``; only the modules that test DDS between the nodes of one host
apply tests/harness.py's DDS_BETWEEN_NODES, each saying why); these tests say ``auto`` outright and use a DDS
domain of their own, so no ROS 2 peer of another test (or its lingering discovery data) is seen here.
Nodes of one host talk over shared memory, as by default. A process has a DDS participant exactly when it has
UDP sockets (rospy and shared memory use none).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any, Dict, Iterator, List

import pytest

import harness
from helpers import mrt

pytestmark = pytest.mark.integration

T = 20.0  # per-wait bound, seconds (generous: a loaded machine)
#: a domain only these tests use in this run (the run's own is 1..200)
AUTO_DOMAIN = 201 + os.getpid() % 20


@pytest.fixture
def auto_env(ros_master: harness.RosMaster) -> Iterator[Dict[str, str]]:
    env = {**ros_master.env, "MICROS_RT_ROS2": "auto", "MICROS_RT_DISABLE_SHM": "0",
           "ROS_DOMAIN_ID": str(AUTO_DOMAIN)}
    yield env
    for path in Path("/dev/shm").glob(f"micros_rt_ros2_u{os.getuid()}_*_d{AUTO_DOMAIN}.*"):
        path.unlink(missing_ok=True)


def udp_sockets(pid: int) -> int:
    """UDP sockets the process has open (a Cyclone participant has several; a node without one has none)."""
    udp: set[str] = set()
    for table in ("udp", "udp6"):
        try:
            with open(f"/proc/{pid}/net/{table}") as f:
                udp.update(line.split()[9] for line in f.readlines()[1:])
        except OSError:
            pass
    mine = set()
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if link.startswith("socket:["):
                mine.add(link[8:-1])
    except OSError:
        return 0
    return len(mine & udp)


def with_participant(peers: List[harness.Peer]) -> List[str]:
    return [p.name for p in peers if p.alive() and udp_sockets(p.proc.pid) > 0]


def watchers(peer: harness.Peer) -> bool:
    return any("watches DDS domain" in (e.get("text") or "") for e in peer.events("log"))


def wait_until(predicate: Any, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout:.0f} s: {what}")
        time.sleep(0.05)


def ros2(*args: Any) -> List[str]:
    return harness.ros2_peer_argv(*[str(a) for a in args])


@pytest.mark.parametrize("cyclonedds_uri", [True, False], ids=["CYCLONEDDS_URI", "no_CYCLONEDDS_URI"])
def test_no_ros2_one_participant_then_an_rclpy_node_hears_and_is_heard(auto_env: Dict[str, str],
                                                                        spawn: harness.Spawner,
                                                                        cyclonedds_uri: bool) -> None:
    """In both environments users have: CYCLONEDDS_URI set (as ROS 2 users set it) and unset (micros_rt's rule)."""
    if not cyclonedds_uri:
        auto_env.pop("CYCLONEDDS_URI", None)
    talker = spawn(mrt("talk", "--topic", "/auto/out", "--count", 100000, "--rate", 20, "--duration", 90,
                       "--node-name", "mrt_talker_auto"), env=auto_env, name="mrt_talker")
    near = spawn(mrt("listen", "--topic", "/auto/out", "--duration", 90, "--node-name", "near"), env=auto_env, name="mrt_listener")
    far = spawn(mrt("listen", "--topic", "/auto/in", "--duration", 90, "--node-name", "far"), env=auto_env, name="mrt_ros2_listener")
    nodes = [talker, near, far]
    for peer in (near, far):
        peer.wait_for("ready", T)
    first = near.wait_for("recv", T)
    assert first["transport"] == "SHM", first
    # one node of the three watches the domain; the others have no participant
    wait_until(lambda: sum(watchers(p) for p in nodes) == 1, T, "one node watching the DDS domain")
    near.wait_for_count("recv", 40, T)
    watcher = [p.name for p in nodes if watchers(p)]
    assert with_participant(nodes) == watcher, [(p.name, udp_sockets(p.proc.pid)) for p in nodes]

    # a ROS 2 node with no endpoint on these topics (rclpy's graph calls): the host's one presence shows it every
    # node and endpoint, with their QoS, and no node makes a participant for it (before: all three did)
    info = spawn(ros2("info", "--topic", "/auto/out", "--wait", T, "--min-publishers", 1, "--min-subscriptions", 1,
                      "--wait-node", "mrt_talker_auto,near", "--duration", 30), env=auto_env, name="rclpy_info")
    graph = info.wait_for("info", T + 10)
    assert [(p["node_name"], p["qos"]["reliability"], p["qos"]["durability"]) for p in graph["publishers"]] == \
        [("mrt_talker_auto", "reliable", "volatile")], graph
    assert [s["node_name"] for s in graph["subscriptions"]] == ["near"], graph
    assert {("/", n) for n in ("mrt_talker_auto", "near", "far")} <= {tuple(n) for n in graph["nodes"]}, graph
    count = len(near.events("recv"))
    near.wait_for_count("recv", count + 20, T)  # a second more: every node's housekeeping ran twice
    assert with_participant(nodes) == watcher, [(p.name, udp_sockets(p.proc.pid)) for p in nodes]

    # an rclpy node appears: it hears the micros_rt talker, and its talker reaches the micros_rt listener
    listener = spawn(ros2("listen", "--topic", "/auto/out", "--count", 5, "--duration", 60),
                     env=auto_env, name="rclpy_listener")
    ros2_talker = spawn(ros2("talk", "--topic", "/auto/in", "--count", 1000, "--rate", 20, "--duration", 60),
                        env=auto_env, name="rclpy_talker")
    ready = listener.wait_for("ready", T)
    heard = listener.wait_for("recv", T)
    talker_ready = ros2_talker.wait_for("ready", T)
    got = far.wait_for("recv", T)
    print(f"\nauto visibility: an rclpy listener heard the micros_rt talker {heard['_rx'] - ready['_rx']:.2f} s after "
          f"it was ready; a micros_rt listener heard an rclpy talker {got['_rx'] - talker_ready['_rx']:.2f} s after "
          f"that was ready")
    assert got["transport"] == "DDS", got
    # only the nodes a ROS 2 endpoint exchanges data with make DDS entities (and the watcher has its participant)
    assert set(with_participant(nodes)) == {"mrt_talker", "mrt_ros2_listener", *watcher}, \
        [(p.name, udp_sockets(p.proc.pid)) for p in nodes]
    heard_data = [int(str(e["data"]).split()[-1]) for e in listener.wait_for_count("recv", 5, T)]
    assert heard_data == list(range(heard_data[0], heard_data[0] + 5)), heard_data  # none lost once heard

    # the local subscriber keeps its shared-memory link and gets every message once
    count = len(near.events("recv"))
    near.wait_for_count("recv", count + 40, T)
    data = [e["data"] for e in near.events("recv")]
    assert len(data) == len(set(data)), "a message delivered twice (shared memory and DDS)"
    assert {e["transport"] for e in near.events("recv")} == {"SHM"}


def test_an_rclpy_node_started_first_is_heard(auto_env: Dict[str, str], spawn: harness.Spawner) -> None:
    ros2_talker = spawn(ros2("talk", "--topic", "/auto/early", "--count", 1000, "--rate", 20, "--duration", 60),
                        env=auto_env, name="rclpy_talker")
    ros2_talker.wait_for("ready", T)
    listener = spawn(mrt("listen", "--topic", "/auto/early", "--duration", 60), env=auto_env, name="mrt_listener")
    ready = listener.wait_for("ready", T)
    got = listener.wait_for("recv", T)
    print(f"\nauto visibility: a micros_rt listener started after an rclpy talker heard it "
          f"{got['_rx'] - ready['_rx']:.2f} s after it was ready")
    assert got["transport"] == "DDS", got


def test_the_watcher_killed_another_node_takes_over(auto_env: Dict[str, str], spawn: harness.Spawner) -> None:
    nodes = [spawn(mrt("talk", "--topic", f"/auto/t{i}", "--count", 100000, "--rate", 10, "--duration", 90,
                       "--node-name", f"talker{i}"),
                   env=auto_env, name=f"mrt_talker{i}") for i in range(2)]
    for peer in nodes:
        peer.wait_for("ready", T)
    wait_until(lambda: sum(watchers(p) for p in nodes) == 1, T, "one node watching the DDS domain")
    watcher = next(p for p in nodes if watchers(p))
    survivor = next(p for p in nodes if p is not watcher)
    os.kill(watcher.proc.pid, signal.SIGKILL)
    wait_until(lambda: watchers(survivor), T, "the other node watching the domain after the watcher died")
    topic = "/auto/t0" if survivor is nodes[0] else "/auto/t1"
    listener = spawn(ros2("listen", "--topic", topic, "--count", 3, "--duration", 60), env=auto_env,
                     name="rclpy_listener")
    listener.wait_for("ready", T)
    listener.wait_for("recv", T)


def children(pid: int) -> List[int]:
    """The child processes of ``pid`` (a micros_rt process's ROS 2 helper is one)."""
    found: List[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return found


def test_a_node_offering_a_service_starts_no_helper_until_a_ros2_node_comes_and_the_helper_is_no_ros2_node(
        auto_env: Dict[str, str], spawn: harness.Spawner) -> None:
    """A robot with no ROS 2 node pays nothing for its services' ROS 2 side: the rclpy helper process starts once a
    ROS 2 node is on the domain (before, every process offering a service started one at once: a Python process
    with rclpy and a Fast DDS participant per node). An rclpy client then gets its answers. The helper is a DDS
    participant but no ROS 2 node: it must not make the host's nodes ROS 2-visible (before issue 41 it did, and a
    60-node ring with one service cost 2.2x rospy's CPU); the watcher's marker goes when the client leaves, with
    the helper still running."""
    service = "/auto/trigger"
    server = spawn([harness.MICROS_RT_PYTHON, str(harness.PEERS_DIR / "ros1_service_peer.py"), "--impl", "micros_rt",
                    "serve", "--services", json.dumps([{"name": service, "type": "std_srvs/Trigger"}]),
                    "--seconds", "90"], env=auto_env, name="mrt_server")
    talker = spawn(mrt("talk", "--topic", "/auto/svc_out", "--count", 100000, "--rate", 20, "--duration", 90),
                   env=auto_env, name="mrt_talker")
    listener = spawn(mrt("listen", "--topic", "/auto/svc_out", "--duration", 90, "--node-name", "svc_near"),
                     env=auto_env, name="mrt_listener")
    ready = server.wait_for("ready", 2 * T)
    assert ready["ros2"] == [service] and ready["waiting"] == [service], ready
    assert listener.wait_for("recv", 2 * T)["transport"] == "SHM"
    nodes = [talker, listener]

    def said(peer: harness.Peer, words: str) -> bool:  # in a JSON log event, or rospy's own output of the server
        return any(words in (e.get("text") or e.get("line") or "") for e in peer.events()) or \
            words in peer.stderr_tail(400)

    marker = Path(f"/dev/shm/micros_rt_ros2_u{os.getuid()}_n{os.stat('/proc/self/ns/net').st_ino}_d{AUTO_DOMAIN}.seen")
    from micros_rt.transports.dds.watch import watcher_pid
    lock = marker.with_suffix(".lock")
    pids = {p.proc.pid for p in [server, *nodes]}
    wait_until(lambda: watcher_pid(str(lock)) in pids, 2 * T, "a micros_rt process watching the domain (lock held)")
    count = len(listener.events("recv"))
    listener.wait_for_count("recv", count + 30, 2 * T)  # a second and a half more: the housekeeping ticks ran
    assert children(server.proc.pid) == [], "the service's ROS 2 helper started with no ROS 2 node on the domain"
    assert not marker.exists(), marker.read_text()
    assert len(with_participant([server, *nodes])) <= 1, [(p.name, udp_sockets(p.proc.pid)) for p in nodes]

    client = spawn([harness.ROS2_PYTHON, str(harness.PEERS_DIR / "ros2_service_peer.py"), "call", "--plan",
                    json.dumps([{"name": service, "type": "std_srvs/srv/Trigger", "count": 3, "timeout": 10,
                                 "wait": 40}])],
                   env=auto_env, name="rclpy_client")
    summary = client.wait_for("summary", 90)
    assert summary["ok"] == 3, summary
    helpers = children(server.proc.pid)
    assert len(helpers) == 1, helpers
    # the client gone, the helper stays; whichever process watches says the helper is micros_rt's, and the
    # marker goes: the helper alone is no ROS 2 node, no node made a participant for it
    client.wait(timeout=30)
    wait_until(lambda: not marker.exists(), 3 * T, "the marker gone once the rclpy client left, the helper running")
    wait_until(lambda: any(said(p, "ROS 2 helper joined") for p in [server, *nodes]), 2 * T,
               "the watcher saying the helper is micros_rt's")
    assert children(server.proc.pid) == helpers
    # the client used the service, no topic: the topics' nodes kept off DDS (the watcher's participant at most)
    assert len(with_participant(nodes)) <= 1, [(p.name, udp_sockets(p.proc.pid)) for p in nodes]
