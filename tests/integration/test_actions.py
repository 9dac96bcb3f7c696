"""Actions both ways: micros_rt's offer_action_to_ros2/offer_ros2_action between stock actionlib and real rclpy
peers.

Processes (all real, see DESIGN.md): a rosmaster; tests/peers/ros1_action_peer.py as stock actionlib servers and
clients (/usr/bin/python3, no micros_rt) and as the micros_rt process between the two worlds (``bridge``, project
venv); tests/peers/ros2_action_peer.py as rclpy action servers and clients (Fast DDS, .venv-ros2). Type:
test_msgs/Fibonacci, which no ROS 1 package has (built at run time on the ROS 1 side), mapped to ROS 2's
test_msgs/action/Fibonacci. One bridge and one server of each kind serve the whole module.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterator, List

import pytest

import harness

pytestmark = pytest.mark.integration

P = f"/act{os.getpid()}"
PEER1 = str(harness.PEERS_DIR / "ros1_action_peer.py")
PEER2 = str(harness.PEERS_DIR / "ros2_action_peer.py")
T = 40.0                  # bound on a peer's start or whole plan
ACCEPT_TIMEOUT = 2.0      # the bridge's accept_timeout
# a cancel is forwarded at once (median ~5 ms, docs/actions.md), not on a tick nor after the goal ends: issue 35's
# 100 ms is a figure measured and printed here, not asserted (a loaded CI run took 107 ms once)
CANCEL_BOUND = 0.5


def stock(mode: str, *args: str) -> List[str]:
    return [harness.STOCK_PYTHON, PEER1, mode, *args]


def ros2(mode: str, *args: str) -> List[str]:
    return [harness.ROS2_PYTHON, PEER2, mode, *args]


def result(peer: harness.Peer, label: str) -> Dict[str, Any]:
    found = [e for e in peer.events("result") if e.get("label") == label]
    assert found, f"no result for {label}: {peer.events()[-8:]}\n{peer.stderr_tail()}"
    return found[0]


def cancel_latency(client: harness.Peer, server: harness.Peer, label: str, name: str) -> float:
    """Seconds from the client's cancel call to the server's cancel callback (one host, one clock)."""
    sent = [e for e in client.events("cancel_sent") if e["label"] == label][0]["t"]
    received = server.wait_for(lambda e: e.get("event") == "cancel_received" and e.get("name", name) == name
                               and e["t"] >= sent - 0.001, 5.0)["t"]
    return float(received - sent)


@pytest.fixture(scope="module")
def graph(ros_master: harness.RosMaster) -> Iterator[Dict[str, harness.Peer]]:
    """Stock actionlib servers, an rclpy action server and the micros_rt bridge, started together."""
    env = dict(ros_master.env)
    peers = {
        "r1": harness.Peer(stock("serve", "--name", f"{P}/r1/fib"), env, name="stock_action_server"),
        "r1_dying": harness.Peer(stock("serve", "--name", f"{P}/r1/dying", "--die-after", "5"), env,
                                 name="stock_dying_server"),
        # the deaf client's (its goals would preempt another's on an actionlib SimpleActionServer)
        "r1_deaf": harness.Peer(stock("serve", "--name", f"{P}/r1/deaf"), env, name="stock_deaf_server"),
        "r2": harness.Peer(ros2("serve", "--actions", json.dumps([
            {"name": f"{P}/r2/fib"}, {"name": f"{P}/r2/silent", "mode": "silent"}])), env, name="ros2_action_server"),
        "bridge": harness.Peer([harness.MICROS_RT_PYTHON, PEER1, "bridge",
                                "--to-ros2", f"{P}/r1/fib", f"{P}/r1/dying", f"{P}/r1/deaf",
                                "--from-ros2", f"{P}/r2/fib", f"{P}/r2/silent", f"{P}/r2/none",
                                "--expect", f"{P}/r2/fib", f"{P}/r2/silent",
                                "--accept-timeout", str(ACCEPT_TIMEOUT),
                                "--call-in-process", f"{P}/r2/fib"], env, name="mrt_action_bridge"),
    }
    try:
        for peer in peers.values():
            peer.wait_for("ready", T)
        assert not peers["bridge"].events("error"), peers["bridge"].events("error")
        yield peers
    finally:
        for peer in peers.values():
            if peer.alive():
                peer.proc.send_signal(2)
        for peer in peers.values():
            peer.stop()


def test_rclpy_client_drives_actionlib_server(graph: Dict[str, harness.Peer], spawn: Any) -> None:
    ready = graph["bridge"].events("ready")[0]
    assert ready["types"][f"{P}/r1/fib"] == "test_msgs/action/Fibonacci", ready
    # a client whose goal response the helper can never send (see test_services' deaf client): rclpy's ActionServer
    # only warns; the helper sends it again for 10 s, then counts it lost and says so. The client waits 20 s.
    deaf = spawn(ros2("call", "--plan", json.dumps([
        {"label": "deaf", "name": f"{P}/r1/deaf", "order": 1, "wait": 20, "timeout": 20,
         "goal_durability": "transient_local"}])), name="ros2_deaf_action_client")
    client = spawn(ros2("call", "--plan", json.dumps([
        {"label": "fib", "name": f"{P}/r1/fib", "order": 100, "wait": 20},
        {"label": "cancel", "name": f"{P}/r1/fib", "order": 5000, "cancel_after": 5}])), name="ros2_action_client")
    client.wait_for("done", T)
    fib = result(client, "fib")
    # every one of the 100 feedback messages, in order, and the result
    assert (fib["status_name"], fib["feedback"], fib["feedback_in_order"], fib["sequence_ok"]) == \
        ("SUCCEEDED", 100, True, True), fib
    cancel = result(client, "cancel")
    assert cancel["status_name"] == "CANCELED" and cancel["feedback_in_order"], cancel
    latency = cancel_latency(client, graph["r1"], "cancel", f"{P}/r1/fib")
    print(f"rclpy -> actionlib: 100/100 feedback, cancel reached the ROS 1 server in {latency * 1e3:.1f} ms")
    assert 0 <= latency < CANCEL_BOUND, latency
    assert graph["r1"].wait_for(lambda e: e.get("event") == "finished" and e["status"] == "PREEMPTED", 5.0)
    deaf.wait_for("done", T)
    assert result(deaf, "deaf")["status_name"] == "TIMEOUT"
    harness.wait_until(lambda: "an action's goal response is lost" in graph["bridge"].stderr_tail(200), T,
                       message="the helper's word on the goal response its client could never take:\n"
                       + graph["bridge"].stderr_tail(20))


def test_actionlib_client_drives_rclpy_server(graph: Dict[str, harness.Peer], spawn: Any) -> None:
    client = spawn(stock("call", "--plan", json.dumps([
        {"label": "fib", "name": f"{P}/r2/fib", "order": 100, "wait": 20},
        {"label": "cancel", "name": f"{P}/r2/fib", "order": 5000, "cancel_after": 5}])), name="stock_action_client")
    client.wait_for("done", T)
    fib = result(client, "fib")
    assert (fib["status_name"], fib["feedback"], fib["feedback_in_order"], fib["sequence_ok"]) == \
        ("SUCCEEDED", 100, True, True), fib
    assert fib["text"] == "succeeded on the ROS 2 action server", fib
    cancel = result(client, "cancel")
    assert cancel["status_name"] == "PREEMPTED" and cancel["feedback_in_order"], cancel
    latency = cancel_latency(client, graph["r2"], "cancel", f"{P}/r2/fib")
    print(f"actionlib -> rclpy: 100/100 feedback, cancel reached the ROS 2 server in {latency * 1e3:.1f} ms")
    assert 0 <= latency < CANCEL_BOUND, latency
    # actionlib's client inside the micros_rt process itself reaches the ROS 2 server the same way
    inside = graph["bridge"].wait_for("in_process_result", T)
    assert (inside["status"], inside["feedback"], inside["feedback_in_order"], inside["sequence_ok"]) == \
        (3, 100, True, True), inside


def test_bad_input_reaches_the_caller_in_words(graph: Dict[str, harness.Peer], spawn: Any) -> None:
    # a ROS 2 server that never answers the goal: the stock ROS 1 client's goal is rejected in words
    ros1_client = spawn(stock("call", "--plan", json.dumps([
        {"label": "silent", "name": f"{P}/r2/silent", "order": 10, "wait": 20, "timeout": 10},
        {"label": "none", "name": f"{P}/r2/none", "order": 10, "wait": 20, "timeout": 10},
        {"label": "after", "name": f"{P}/r2/fib", "order": 10}])), name="stock_action_client")
    # a ROS 1 server that dies mid-goal (SIGKILL after 5 feedback messages): the rclpy client's goal is aborted
    ros2_client = spawn(ros2("call", "--plan", json.dumps([
        {"label": "dies", "name": f"{P}/r1/dying", "order": 100, "wait": 20, "timeout": 10},
        {"label": "after", "name": f"{P}/r1/fib", "order": 10}])), name="ros2_action_client")
    ros1_client.wait_for("done", T)
    ros2_client.wait_for("done", T)

    silent = result(ros1_client, "silent")
    assert silent["status_name"] == "REJECTED", silent
    assert silent["text"] == (f"action {P}/r2/silent: the ROS 2 action server did not answer the goal within "
                              f"{ACCEPT_TIMEOUT:g} s"), silent
    assert ACCEPT_TIMEOUT - 0.2 < silent["elapsed"] < ACCEPT_TIMEOUT + 1.5, silent
    # no ROS 2 server of the name at all: the same, with other words
    none = result(ros1_client, "none")
    assert none["status_name"] == "REJECTED" and none["elapsed"] < ACCEPT_TIMEOUT + 1.5, none
    assert none["text"].startswith(f"action {P}/r2/none: no ROS 2 action server of {P}/r2/none was discovered "
                                   f"within {ACCEPT_TIMEOUT:g} s (ROS_DOMAIN_ID "), none
    dies = result(ros2_client, "dies")
    # the server sent 5 feedback messages before its SIGKILL; ROS 2 carries feedback (a topic) and the result (a
    # service) apart, and rclpy's client drops feedback it takes after the result: the 5th may lose that race
    # (a full run: 4), never more than 5 arrive. The server's actionlib publishes feedback from a queue (its
    # queue_size 50: a writer thread), so the 4th, sent 5 ms before the kill, may still be in it on a loaded machine
    assert dies["status_name"] == "ABORTED" and 3 <= dies["feedback"] <= 5 and dies["elapsed"] < 5.0, dies
    bridge = graph["bridge"]
    harness.wait_until(lambda: "went away during a ROS 2 client's goal" in bridge.stderr_tail(200), 5.0,
                       message="the bridge's warning about the ROS 1 server that died")
    # the bridge keeps serving both ways
    for client in (ros1_client, ros2_client):
        after = result(client, "after")
        assert (after["status_name"], after["feedback"], after["sequence_ok"]) == ("SUCCEEDED", 10, True), after
    assert bridge.alive() and graph["r1"].alive() and graph["r2"].alive()
    stats = bridge.events("stats")[-1]["stats"]
    assert stats[f"{P}/r2/silent"]["rejected"] >= 1 and stats[f"{P}/r1/dying"]["aborted"] >= 1, stats
    assert all(s["feedback_dropped"] == 0 for s in stats.values()), stats
    # a class that is not an action (the goal instead of FibonacciAction) is refused at once, in words
    wrong = bridge.events("wrong_type")[0]["message"]
    assert wrong.startswith("action_class must be a ROS 1 action class") and "test_msgs/FibonacciGoal" in wrong
