"""Stock nodes through the relay (issue 35, deliverable 3): actions both ways in the ``ros2:`` section, and ``/clock``
from ROS 2 into ROS 1 (ROS 1 -> ROS 2 is in test_relay_ros2.py).

Processes (all real): a rosmaster of its own and ``micros-rt relay``, whose configuration names the two actions and
``/clock`` and nothing about their types, and an rclpy action server that also publishes ``/clock`` as a simulator
does (tests/peers/ros2_action_peer.py, .venv-ros2, Fast DDS on loopback), shared by the tests of this file; then an
rclpy action client, a stock actionlib server started after it (tests/peers/ros1_action_peer.py under
/usr/bin/python3, no micros_rt), a stock actionlib client and stock ``rostopic``. The action type, test_msgs/Fibonacci, is in no ROS 1
package on this host: the relay builds the ROS 1 classes from ROS 2's Fibonacci.action, and the stock peers build
theirs with genpy (tests/peers/ros1_action_types.py); rospy's md5 check at every connection would refuse a mismatch.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
from typing import Any, Dict, Iterator

import pytest

import harness

pytestmark = pytest.mark.integration

CLI = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
PEER1 = str(harness.PEERS_DIR / "ros1_action_peer.py")
PEER2 = str(harness.PEERS_DIR / "ros2_action_peer.py")
P = f"/ra{os.getpid()}"
R1, R2 = f"{P}/r1/fib", f"{P}/r2/fib"   # a ROS 1 server's action (exported), a ROS 2 server's (imported)
RENAMED = f"{P}/r2/renamed"              # a ROS 2 server's action imported under another name: refused in words
CONFIG = f"""\
graph: robot
ros2:
  export: {{{R1}: {{}}}}                  # a stock actionlib server, offered to ROS 2
  import: {{{R2}: {{}}, /clock: {{}}, {RENAMED}: {{as: /elsewhere}}}}   # an rclpy action server, a ROS 2 /clock
"""
T = 40.0               # generous bound on any one wait (the 2-core machine may be busy)
PERIOD = "0.01"        # the servers' feedback period, seconds (100 Hz)
CANCEL_BOUND = 0.100   # issue 35: a cancel reaches the server within 100 ms


class Setup:
    def __init__(self, master: harness.RosMaster, peers: Dict[str, harness.Peer]) -> None:
        self.master, self.peers = master, peers

    def ros2_entry(self, direction: str, name: str, ready: Any) -> Dict[str, Any]:
        """The relay's counters of ``ros2:`` entry ``name`` once ``ready(counters)`` holds."""
        def match(event: Dict[str, Any]) -> bool:
            return event.get("event") == "stats" and any(
                e.get("direction") == direction and e.get("name") == name and ready(e) for e in event.get("ros2", []))

        event = self.peers["relay"].wait_for(match, timeout=T)
        return next(e for e in event["ros2"] if e.get("direction") == direction and e.get("name") == name)


@pytest.fixture(scope="module")
def setup(dds_domain: int, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Setup]:
    work = tmp_path_factory.mktemp("relay_actions")
    master = harness.RosMaster(workdir=work / "master", domain_id=dds_domain)
    master.start()
    peers: Dict[str, harness.Peer] = {}
    try:
        config = work / "relay.yaml"
        config.write_text(CONFIG)
        env = dict(master.env)
        # both start at once: their start-up (imports, DDS discovery) overlaps; the relay finds the server as it comes
        # (every --poll-period). The stock server comes later, in the test.
        peers["relay"] = harness.Peer([CLI, "relay", "--config", str(config), "--json", "--stats-period", "0.5",
                                       "--poll-period", "0.5"], env, name="relay")
        peers["r2"] = harness.Peer([harness.ROS2_PYTHON, PEER2, "serve", "--clock", "--period", PERIOD, "--actions",
                                    json.dumps([{"name": R2}, {"name": RENAMED}])], env, name="ros2_action_server")
        for peer in peers.values():
            peer.wait_for("ready", timeout=T)
        yield Setup(master, peers)
    finally:
        for peer in reversed(list(peers.values())):
            peer.stop()
        master.cleanup()


def _result(peer: harness.Peer, label: str) -> Dict[str, Any]:
    found = [e for e in peer.events("result") if e.get("label") == label]
    assert found, f"no result for {label}: {peer.events()[-8:]}\n{peer.stderr_tail()}"
    return found[0]


def _cancel_latency(client: harness.Peer, server: harness.Peer, label: str, name: str) -> float:
    """Seconds from the client's cancel call to the server's cancel callback (one host, one clock)."""
    sent = [e for e in client.events("cancel_sent") if e["label"] == label][0]["t"]
    received = server.wait_for(lambda e: e.get("event") == "cancel_received" and e.get("name", name) == name
                               and e["t"] >= sent - 0.001, 5.0)["t"]
    return float(received - sent)


def test_actions_both_ways(setup: Setup, spawn: Any) -> None:
    plan = [{"label": "fib", "order": 100, "wait": 30}, {"label": "cancel", "order": 5000, "cancel_after": 5}]
    env = dict(setup.master.env)
    # an rclpy ActionClient of the stock server's action, waiting for it before the stock server exists: its goal
    # goes out as soon as the relay offers the action to ROS 2, just after the relay found the server
    ros2_client = spawn([harness.ROS2_PYTHON, PEER2, "call", "--plan",
                         json.dumps([{**step, "name": R1} for step in plan])], env, name="ros2_action_client")
    r1 = spawn([harness.STOCK_PYTHON, PEER1, "serve", "--name", R1, "--period", PERIOD], env,
               name="stock_action_server")
    r1.wait_for("ready", T)
    ros2_client.wait_for("done", T)
    # then a stock actionlib client of the rclpy server's action (one after the other: 2 cores, and rclpy's
    # ActionClient drops a feedback message it takes after the result, so a starved client could miss the last one)
    ros1_client = spawn([harness.STOCK_PYTHON, PEER1, "call", "--plan",
                         json.dumps([{**step, "name": R2} for step in plan])], env, name="stock_action_client")
    # meanwhile, `micros-rt action list` (issue 43): both actions, their types and servers on each side
    listing = subprocess.Popen([CLI, "action", "list", "--json", "--wait", "4"], env=env, stdin=subprocess.DEVNULL,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ros1_client.wait_for("done", T)
    out, err = listing.communicate(timeout=60)
    assert listing.returncode == 0 and "Traceback" not in err, (listing.returncode, out, err)
    rows = {a["name"]: a for a in json.loads(out)["actions"]}
    fib_types = ("test_msgs/FibonacciAction", "test_msgs/action/Fibonacci")
    assert (rows[R1]["side"], rows[R1]["ros1_type"], rows[R1]["ros2_type"], rows[R1]["ros2_servers"],
            rows[R1]["carried"]) == ("ROS 1+2", *fib_types, ["/relay_robot (relay, its ROS 2 helper)"],
                                     [f"relay /relay_robot: ROS 1 {R1} -> ROS 2 {R1}"]), rows[R1]
    assert [s.startswith(f"/stock_action_server_{r1.pid}_") for s in rows[R1]["ros1_servers"]] == [True], rows[R1]
    assert (rows[R2]["side"], rows[R2]["ros1_servers"], rows[R2]["carried"]) == (
        "ROS 1+2", ["/relay_robot (relay)"], [f"relay /relay_robot: ROS 2 {R2} -> ROS 1 {R2}"]), rows[R2]
    assert len(rows[R2]["ros2_servers"]) == 1 and rows[R2]["ros2_servers"][0].startswith("/ros2_action_serve"), rows[R2]
    # goal, every one of the 100 feedback messages in order, and the result, both ways
    said = [e["line"] for e in setup.peers["relay"].events("_raw") if "action" in e.get("line", "")]
    said += [e for e in (setup.peers["relay"].events("stats") or [{}])[-1].get("ros2", []) if e.get("kind") == "action"]
    for client in (ros2_client, ros1_client):
        fib = _result(client, "fib")
        if (fib["status_name"], fib["feedback"], fib["feedback_in_order"], fib["sequence_ok"]) != \
                ("SUCCEEDED", 100, True, True):
            print(f"{client.name}: {fib}\nthe relay: {json.dumps(said, indent=1)}\n{setup.peers['relay'].stderr_tail()}")
        assert (fib["status_name"], fib["feedback"], fib["feedback_in_order"], fib["sequence_ok"]) == \
            ("SUCCEEDED", 100, True, True), (client.name, fib)
    assert _result(ros1_client, "fib")["text"] == "succeeded on the ROS 2 action server"
    # cancel, both ways: the goal ends cancelled (CANCELED in ROS 2's words, PREEMPTED in actionlib's) and the
    # server's cancel callback ran within 100 ms of the client's cancel
    assert _result(ros2_client, "cancel")["status_name"] == "CANCELED", _result(ros2_client, "cancel")
    assert _result(ros1_client, "cancel")["status_name"] == "PREEMPTED", _result(ros1_client, "cancel")
    to_ros1 = _cancel_latency(ros2_client, r1, "cancel", R1)
    to_ros2 = _cancel_latency(ros1_client, setup.peers["r2"], "cancel", R2)
    print(f"through the relay: rclpy client -> stock server 100/100 feedback, cancel in {to_ros1 * 1e3:.1f} ms; "
          f"stock client -> rclpy server 100/100 feedback, cancel in {to_ros2 * 1e3:.1f} ms")
    assert 0 <= to_ros1 < CANCEL_BOUND and 0 <= to_ros2 < CANCEL_BOUND, (to_ros1, to_ros2)
    assert r1.wait_for(lambda e: e.get("event") == "finished" and e["status"] == "PREEMPTED", T)
    assert setup.peers["r2"].wait_for(lambda e: e.get("event") == "finished" and e["status"] == "CANCELED", T)
    # the relay's counters: each entry learnt it is an action, its type built from ROS 2's definition
    for direction, name in (("export", R1), ("import", R2)):
        entry = setup.ros2_entry(direction, name, lambda e: e.get("succeeded", 0) >= 1 and e.get("canceled", 0) >= 1)
        assert (entry["kind"], entry["type"], entry["ros2_type"]) == \
            ("action", "test_msgs/FibonacciAction", "test_msgs/action/Fibonacci"), entry
        assert entry["type_source"].startswith("built from ") and entry["type_source"].endswith("Fibonacci.action")
        assert (entry["goals"], entry["accepted"], entry["rejected"], entry["feedback_dropped"]) == (2, 2, 0, 0), entry
        assert entry["feedback"] >= 105, entry
    # the ROS 1 graph has one server of the ROS 1 action (the stock one) and one of the imported (the relay)
    publishers = harness.system_state(setup.master)["publishers"]
    assert [n for n in publishers.get(f"{R1}/status", []) if n.startswith("/relay")] == [], publishers
    assert [n for n in publishers.get(f"{R2}/status", [])] == ["/relay_robot"], publishers


def _tool(master: harness.RosMaster, *args: str) -> str:
    cp = subprocess.run([harness.STOCK_PYTHON, harness.ROSTOPIC, *args], env=master.env, stdin=subprocess.DEVNULL,
                        capture_output=True, text=True, timeout=T)
    assert cp.returncode == 0, f"rostopic {' '.join(args)} exited {cp.returncode}:\n{cp.stdout}\n{cp.stderr}"
    return cp.stdout


def test_ros2_clock_reaches_stock_ros1(setup: Setup) -> None:
    # a ROS 2 simulator's /clock (rosgraph_msgs/msg/Clock) is rosgraph_msgs/Clock in ROS 1, published by the relay
    incoming = setup.ros2_entry("import", "/clock", lambda e: e.get("published", 0) >= 1)
    assert incoming["kind"] == "topic" and incoming["refused"] == 0, incoming
    info = _tool(setup.master, "info", "/clock")
    assert "Type: rosgraph_msgs/Clock" in info and "/relay_robot" in info, info
    echoed = _tool(setup.master, "echo", "-n", "3", "/clock")
    ticks = [(int(s), int(n)) for s, n in re.findall(r"secs: (\d+)\s+nsecs:\s+(\d+)", echoed)]
    # the peer's clock: 2000 s + n * 0.1 s, increasing
    assert len(ticks) == 3 and all(s >= 2000 and n % 100_000_000 == 0 for s, n in ticks), echoed
    assert ticks == sorted(set(ticks)), echoed


def test_an_action_that_cannot_be_carried_is_said_in_words(setup: Setup) -> None:
    # found to be an action in DDS discovery, but 'as:' would rename it: refused in words, naming the entry's line
    event = setup.peers["relay"].wait_for(lambda e: e.get("event") == "stats" and any(
        RENAMED in why for why in e.get("not_carried", {}).values()), timeout=T)
    why = next(w for w in event["not_carried"].values() if RENAMED in w)
    assert "relay.yaml:4" in why and "an action keeps its name on both sides" in why, why
    assert harness.system_state(setup.master)["publishers"].get(f"{RENAMED}/status") is None
    assert harness.system_state(setup.master)["publishers"].get("/elsewhere/status") is None
