"""``micros-rt topic list`` and ``micros-rt node list``: the ROS 1 master's graph and ROS 2's (DDS discovery)
in one list, each entry marked ROS 1, ROS 2 or ROS 1+2 (issue 35, deliverable 4).

One graph serves the module: a stock rospy talker (/usr/bin/python3, no micros_rt) on /both_stock, a micros_rt
talker on /both_mrt, an rclpy listener of /both_mrt and an rclpy talker on /both_ros2 (.venv-ros2, Fast DDS
on loopback). The CLI runs as a subprocess with the master's environment (loopback DDS, this run's domain);
each check polls it until the expected rows appear (bounded), as discovery takes its time.
"""

from __future__ import annotations

import json
import re
import subprocess
from typing import Dict, Iterator, List, Mapping, Tuple

import pytest

import harness
from helpers import mrt, stock_talker

pytestmark = pytest.mark.integration

CLI = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
T = 30.0  # bound of each wait, seconds

STOCK_TOPIC, MRT_TOPIC, ROS2_TOPIC = "/both_stock", "/both_mrt", "/both_ros2"
STOCK_NODE, MRT_NODE = "/both_stock_talker", "/both_mrt_talker"
R2_TALKER, R2_LISTENER = "/both_r2_talker", "/both_r2_listener"


def cli(env: Mapping[str, str], *args: str, timeout: float = 60.0) -> "subprocess.CompletedProcess[str]":
    try:
        return subprocess.run([CLI, *args], env=dict(env), stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"micros-rt {' '.join(args)} did not finish in {timeout} s: {exc.stdout!r}") from None


def table(text: str) -> Dict[str, List[str]]:
    """A ``list`` table's rows by first column (columns are separated by two spaces or more)."""
    rows = [re.split(r"\s{2,}", line.strip()) for line in text.splitlines() if line.strip()]
    names = [r[0] for r in rows[1:]]
    assert len(names) == len(set(names)), f"a name listed twice: {text}"
    return {r[0]: r[1:] for r in rows[1:]}


def poll(env: Mapping[str, str], args: Tuple[str, ...], expected: Dict[str, List[str]]) -> Dict[str, List[str]]:
    """Run ``micros-rt ARGS`` until every expected row starts with the expected cells; the last table."""
    last: List[object] = [None]

    def seen() -> Dict[str, List[str]]:
        cp = cli(env, *args)
        assert cp.returncode == 0 and "Traceback" not in cp.stderr, (cp.returncode, cp.stdout, cp.stderr)
        rows = table(cp.stdout)
        last[0] = (cp.stdout, cp.stderr)
        ok = all(rows.get(name, [])[:len(cells)] == cells for name, cells in expected.items())
        return rows if ok else {}

    try:
        return dict(harness.wait_until(seen, T, interval=0.2, message=f"micros-rt {' '.join(args)}: {expected}"))
    except AssertionError as exc:
        raise AssertionError(f"{exc}; last output: {last[0]}") from None


@pytest.fixture(scope="module")
def graph(ros_master: harness.RosMaster) -> Iterator[Dict[str, str]]:
    spawner = harness.Spawner(ros_master.env)
    try:
        peers = [
            spawner(harness.ros2_peer_argv("listen", "--topic", MRT_TOPIC, "--node-name", R2_LISTENER[1:], "--count",
                                           "0", "--duration", "120"), name="rclpy_listener"),
            spawner(harness.ros2_peer_argv("talk", "--topic", ROS2_TOPIC, "--node-name", R2_TALKER[1:], "--count",
                                           "0", "--rate", "2", "--duration", "120"), name="rclpy_talker"),
            spawner(stock_talker("--topic", STOCK_TOPIC, "--node-name", STOCK_NODE[1:], "--count", 0, "--rate", 2,
                                 "--duration", 120), name="stock_talker"),
            spawner(mrt("talk", "--topic", MRT_TOPIC, "--node-name", MRT_NODE[1:], "--count", 100000, "--rate", 5,
                        "--duration", 120), name="mrt_talker"),
        ]
        for peer in peers:  # each has its endpoint; the CLI's polls wait for discovery
            peer.wait_for("ready", T)
        yield dict(ros_master.env)
    finally:
        spawner.close()


def test_topic_list_marks_ros1_ros2_and_both(graph: Dict[str, str]) -> None:
    rows = poll(graph, ("topic", "list"), {
        STOCK_TOPIC: ["ROS 1", "std_msgs/String", "1/0", "-"],
        # the micros_rt talker counts once, under ROS 1; the rclpy listener under ROS 2
        MRT_TOPIC: ["ROS 1+2", "std_msgs/String", "1/0", "0/1"],
        ROS2_TOPIC: ["ROS 2", "std_msgs/msg/String", "-", "1/0"],
    })
    assert not [name for name in rows if name.startswith("rt/")], rows  # DDS names are ROS names here
    cp = cli(graph, "topic", "list", "-v")
    assert cp.returncode == 0, cp.stderr
    text = cp.stdout
    assert re.search(rf"^{MRT_TOPIC}  \[ROS 1\+2\]  std_msgs/String$", text, re.M), text
    assert re.search(rf"ROS 1 publishers: +{MRT_NODE} \(micros_rt, also on DDS\)", text), text
    assert re.search(rf"ROS 2 subscribers: +{R2_LISTENER}$", text, re.M), text
    assert re.search(rf"^{ROS2_TOPIC}  \[ROS 2\]  std_msgs/msg/String\n +ROS 2 publishers: +{R2_TALKER}$",
                     text, re.M), text
    assert re.search(rf"^{STOCK_TOPIC}  \[ROS 1\]  std_msgs/String\n +ROS 1 publishers: +{STOCK_NODE}$",
                     text, re.M), text
    # the master away: topic info shows the ROS 2 side, and says the ROS 1 side is unknown, not empty
    cp = cli(dict(graph, ROS_MASTER_URI=f"http://127.0.0.1:{harness.free_tcp_port()}/"), "topic", "info", MRT_TOPIC)
    assert cp.returncode == 0 and "Traceback" not in cp.stderr, (cp.returncode, cp.stdout, cp.stderr)
    assert "Publishers: unknown (the ROS 1 master's list: " in cp.stdout, cp.stdout
    assert "Publishers: None" not in cp.stdout and re.search(rf"^ \* {R2_LISTENER}", cp.stdout, re.M), cp.stdout


def test_node_list_marks_each_node_and_rclpy_names_the_micros_rt_node(graph: Dict[str, str],
                                                                       spawn: harness.Spawner) -> None:
    # ROS 2's own view, from an rclpy node (started first: it runs while the CLI is polled)
    info = spawn(harness.ros2_peer_argv("info", "--topic", MRT_TOPIC, "--min-publishers", "1", "--min-subscriptions",
                                        "1", "--wait-node", f"{MRT_NODE[1:]},{R2_LISTENER[1:]}", "--wait", "20",
                                        "--duration", "25"), env=graph, name="rclpy_info")
    expected = {STOCK_NODE: ("ROS 1", "stock"), MRT_NODE: ("ROS 1+2", "micros_rt"), R2_TALKER: ("ROS 2", None),
                R2_LISTENER: ("ROS 2", None)}
    last: List[object] = [None]

    def listed() -> bool:
        cp = cli(graph, "node", "list", "-v", "--json")
        assert cp.returncode == 0 and "Traceback" not in cp.stderr, (cp.returncode, cp.stdout, cp.stderr)
        data = last[0] = json.loads(cp.stdout)
        assert data["ros1"]["available"] is True and data["ros2"]["available"] is True, data
        rows = {n["node"]: (n["side"], n["ros1_kind"]) for n in data["nodes"]}
        return all(rows.get(name) == want for name, want in expected.items())

    try:
        harness.wait_until(listed, T, interval=0.2, message=f"micros-rt node list -v --json: {expected}")
    except AssertionError as exc:
        raise AssertionError(f"{exc}; last output: {last[0]}") from None
    # get_node_names_and_namespaces() of an rclpy node names the micros_rt node, as ros2 node list does
    ev = info.wait_for("info", T)
    assert ["/", MRT_NODE[1:]] in ev["nodes"], ev
    assert [p["node_name"] for p in ev["publishers"]] == [MRT_NODE[1:]], ev
    assert [p["node_name"] for p in ev["subscriptions"]] == [R2_LISTENER[1:]], ev
    rclpy_nodes = {ns.rstrip("/") + "/" + name for ns, name in ev["nodes"]}
    assert {MRT_NODE, R2_LISTENER} <= rclpy_nodes and STOCK_NODE not in rclpy_nodes, ev


def test_without_dds_the_ros1_side_is_listed_with_a_note(graph: Dict[str, str]) -> None:
    env = dict(graph, ROS_DOMAIN_ID="999")
    cp = cli(env, "node", "list")
    assert cp.returncode == 0, (cp.stdout, cp.stderr)
    rows = table(cp.stdout)
    assert rows[STOCK_NODE] == ["ROS 1"] and rows[MRT_NODE] == ["ROS 1"] and R2_TALKER not in rows, cp.stdout
    assert "ROS 2 side not listed: ROS_DOMAIN_ID=999 is out of range" in cp.stderr and "Traceback" not in cp.stderr, \
        cp.stderr
    # neither side: one line, exit code 1
    cp = cli(dict(env, ROS_MASTER_URI=f"http://127.0.0.1:{harness.free_tcp_port()}/"), "topic", "list")
    assert cp.returncode == 1 and len(cp.stderr.strip().splitlines()) == 1, (cp.returncode, cp.stderr)
    assert "neither graph can be read: cannot reach the ROS master" in cp.stderr, cp.stderr
