"""The ``micros-rt`` tools against a live graph of real processes (issue 10, items 3-8).

One mixed graph on topic /cli_mixed serves the module: a micros_rt talker (HIGH priority), a micros_rt
best-effort talker, a micros_rt listener (reliable: DDS from the first talker, DDS declined by the
best-effort one) and a stock rospy listener (TCPROS from both). The CLI runs as a subprocess
(``.venv/bin/micros-rt``) with the master's environment: loopback-only DDS on this run's domain, its own
participant included when it subscribes.
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Tuple

import pytest

import harness
from helpers import mrt, stock_listener

# topic info and the graph name DDS links and the declined-DDS reason between two local micros_rt nodes
pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

CLI = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
TOPIC = "/cli_mixed"
TALKER, BEST_EFFORT, LISTENER, STOCK = "/cli_mrt_talker", "/cli_mrt_best_effort", "/cli_mrt_listener", "/cli_stock"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def cli(env: Mapping[str, str], *args: str, timeout: float = 90.0) -> "subprocess.CompletedProcess[str]":
    """Run ``micros-rt ARGS``; bounded, output captured."""
    try:
        return subprocess.run([CLI, *args], env=dict(env), stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"micros-rt {' '.join(args)} did not finish in {timeout} s: {exc.stdout!r}") from None


def assert_one_line_error(cp: "subprocess.CompletedProcess[str]", *, code: int, words: str) -> None:
    assert cp.returncode == code, (cp.returncode, cp.stdout, cp.stderr)
    lines = cp.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert words in lines[0], lines[0]


def links_of(env: Mapping[str, str]) -> Dict[Tuple[str, str], Dict[str, Any]]:
    cp = cli(env, "topic", "info", "--json", TOPIC)
    assert cp.returncode == 0, cp.stderr
    return {(link["publisher"], link["subscriber"]): link for link in json.loads(cp.stdout)["links"]}


EXPECTED = {(TALKER, LISTENER): "DDS", (TALKER, STOCK): "TCPROS", (BEST_EFFORT, LISTENER): "TCPROS",
            (BEST_EFFORT, STOCK): "TCPROS"}


@pytest.fixture(scope="module")
def graph(ros_master: harness.RosMaster) -> Iterator[Dict[str, str]]:
    """The mixed graph, up and linked (every expected link reported by the CLI itself)."""
    spawner = harness.Spawner(ros_master.env)
    try:
        talker = spawner(mrt("talk", "--topic", TOPIC, "--rate", 50, "--count", 9000, "--node-name", TALKER[1:],
                             qos={"transport_priority": "HIGH"}))
        spawner(mrt("talk", "--topic", TOPIC, "--rate", 10, "--count", 1800, "--node-name", BEST_EFFORT[1:],
                    qos={"using_best_effort_protocol": True}))
        listener = spawner(mrt("listen", "--topic", TOPIC, "--duration", 180, "--node-name", LISTENER[1:]))
        stock = spawner(stock_listener("--topic", TOPIC, "--node-name", STOCK[1:], "--duration", 180))
        talker.wait_for("ready", 60)
        listener.wait_for("recv", 60)
        stock.wait_for("recv", 60)

        seen: List[Dict[Tuple[str, str], str]] = [{}]

        def all_linked() -> bool:
            seen[0] = {pair: link["protocol"] for pair, link in links_of(ros_master.env).items()}
            return seen[0] == EXPECTED

        try:
            harness.wait_until(all_linked, 60, interval=0.5, message=f"the four links of {TOPIC} {EXPECTED}")
        except AssertionError as exc:
            raise AssertionError(f"{exc}; last seen {seen[0]}") from None
        _GRAPH_PEERS[:] = list(spawner)
        yield dict(ros_master.env)
    finally:
        _GRAPH_PEERS.clear()
        spawner.close()


_GRAPH_PEERS: List[harness.Peer] = []


@pytest.fixture(autouse=True)
def _graph_still_up() -> Iterator[None]:
    """Each test starts with the module's four nodes alive; a dead one fails with its exit code and stderr."""
    for peer in _GRAPH_PEERS:
        if not peer.alive():
            raise AssertionError(f"{peer!r} of the module's graph exited (returncode {peer.returncode}); "
                                 f"last events {peer.events()[-3:]}\nstderr tail:\n{peer.stderr_tail()}")
    yield


def test_topic_info_names_dds_and_tcpros_links_and_the_declined_reason(graph: Dict[str, str]) -> None:
    links = links_of(graph)
    dds = links[(TALKER, LISTENER)]
    assert (dds["protocol"], dds["transport_priority"], dds["reason"]) == ("DDS", "HIGH", None)
    assert dds["publisher_qos"]["transport_priority"] == "HIGH"
    assert dds["subscriber_qos"]["using_best_effort_protocol"] is False
    to_stock = links[(TALKER, STOCK)]
    assert (to_stock["subscriber_kind"], to_stock["subscriber_qos"]) == ("stock", None)
    assert "stock ROS node" in to_stock["reason"]
    refused = links[(BEST_EFFORT, LISTENER)]
    assert refused["protocol"] == "TCPROS"
    assert refused["verdict"] == "qos:using_best_effort_protocol"
    assert "falling back to TCPROS" in refused["reason"] and "best-effort" in refused["reason"]
    assert refused["publisher_qos"]["using_best_effort_protocol"] is True

    cp = cli(graph, "topic", "info", TOPIC)
    assert cp.returncode == 0, cp.stderr
    text = cp.stdout
    assert "Type: std_msgs/String" in text
    assert f" * {TALKER} -> {LISTENER}: DDS, transport priority HIGH" in text
    assert f" * {TALKER} -> {STOCK}: TCPROS, transport priority HIGH" in text
    assert f" * {BEST_EFFORT} -> {LISTENER}: TCPROS, transport priority NORMAL" in text
    assert f"DDS declined: DDS QoS mismatch with subscriber {LISTENER}, falling back to TCPROS" in text
    assert f" * {STOCK} (" in text and "[stock]" in text


def test_topic_latency_count_json_and_plot(graph: Dict[str, str], tmp_path: Path) -> None:
    plot = tmp_path / "latency.png"
    cp = cli(graph, "topic", "latency", TOPIC, "--count", "100", "--json", "--timeout", "60", "--plot", str(plot))
    assert cp.returncode == 0, (cp.stdout, cp.stderr)
    report = json.loads(cp.stdout)
    assert report["topic"] == TOPIC and report["messages"] >= 100
    assert "DDS" in report["transports"].values()  # the CLI's own subscriber got DDS from the micros_rt talker
    latency = report["latency_ms"]
    assert latency["count"] > 0 and report["timestamps"] == "DDS source timestamps"
    assert 0 <= latency["p50"] <= latency["p99"] <= latency["max"]
    assert report["rate_hz"] > 0 and report["drops"]["total"] == 0
    assert {"deadline_misses", "budget_misses"} <= set(report)
    assert plot.read_bytes()[:8] == PNG_MAGIC and plot.stat().st_size > 5_000


def test_graph_png_and_dot(graph: Dict[str, str], tmp_path: Path) -> None:
    png = tmp_path / "graph.png"
    cp = cli(graph, "graph", "--png", str(png), "--dot")
    assert cp.returncode == 0, cp.stderr
    data = png.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 10_000, len(data)
    dot = cp.stdout
    for node in (TALKER, BEST_EFFORT, LISTENER, STOCK):
        assert f'"n:{node}"' in dot
    assert f'"t:{TOPIC}" -> "n:{LISTENER}" [label="DDS from {TALKER}' in dot
    assert 'color="#1f77b4"' in dot and 'color="#e66100"' in dot
    assert "DDS declined: qos:using_best_effort_protocol" in dot


def test_doctor_passes_on_a_healthy_loopback_setup(graph: Dict[str, str]) -> None:
    cp = cli(graph, "doctor")
    assert cp.returncode == 0, cp.stdout
    assert "all 11 checks passed" in cp.stdout
    assert "[ OK ] ROS 2 helper" in cp.stdout and "rclpy imports" in cp.stdout
    assert "[SKIP] shared memory        turned off by MICROS_RT_DISABLE_SHM" in cp.stdout  # the suite keeps it off
    assert "[ OK ] ROS master" in cp.stdout and "multicast off" in cp.stdout
    assert "micros_rt node(s); largest offset" in cp.stdout  # the graph's micros_rt nodes answered


def _dead_master_env(env: Mapping[str, str]) -> Dict[str, str]:
    return dict(env, ROS_MASTER_URI=f"http://127.0.0.1:{harness.free_tcp_port()}/")


def test_doctor_fails_with_its_fix_when_the_master_is_down(graph: Dict[str, str]) -> None:
    cp = cli(_dead_master_env(graph), "doctor")
    assert cp.returncode == 1, cp.stdout
    lines = cp.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("[FAIL] ROS master"))
    assert "cannot reach the ROS master" in lines[at]
    assert "fix: start roscore" in lines[at + 1]
    assert "1 of 11 checks failed" in cp.stdout


def test_doctor_flags_a_ros2_helper_python_that_is_not_there(graph: Dict[str, str]) -> None:
    cp = cli(dict(graph, MICROS_RT_ROS2_PYTHON="/nonexistent/python"), "doctor")
    assert cp.returncode == 1, cp.stdout
    lines = cp.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("[FAIL] ROS 2 helper"))
    assert "/nonexistent/python cannot run" in lines[at] and "served to ROS 1 only" in lines[at]
    assert "(advertise_service, service_client, offer_action_to_ros2, offer_ros2_action, a relay's ros2: services" \
        in lines[at], lines[at]   # what needs it, in words
    assert "fix: point MICROS_RT_ROS2_PYTHON at the python of an installation with rclpy" in lines[at + 1]


def test_doctor_fails_with_its_fix_for_domain_999(graph: Dict[str, str]) -> None:
    cp = cli(dict(graph, ROS_DOMAIN_ID="999"), "doctor")
    assert cp.returncode == 1, cp.stdout
    lines = cp.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("[FAIL] ROS_DOMAIN_ID"))
    assert "ROS_DOMAIN_ID=999 is out of range" in lines[at]
    assert "fix: export ROS_DOMAIN_ID=0" in lines[at + 1]


def test_profile_check_on_a_good_and_a_bad_file(graph: Dict[str, str], tmp_path: Path) -> None:
    good = tmp_path / "good.yaml"
    good.write_text(f'publishers:\n  {TOPIC}: {{transport_priority: HIGH}}\n  "/cli_*": {{latency_budget: 0.01}}\n'
                    'subscribers:\n  "/nothing/*": {deadline: 0.5}\n')
    cp = cli(graph, "profile", "check", str(good))
    assert cp.returncode == 0, cp.stderr
    out = cp.stdout
    assert "valid (2 publisher rules, 1 subscriber rule)" in out
    assert f"matches {TOPIC}  [{BEST_EFFORT}, {TALKER}]" in out
    assert f"(overridden by '{TOPIC}') {TOPIC}" in out
    assert "matches no live subscriber topic" in out
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"publishers:\n  {TOPIC}:\n    transport_priority: HIGH\n    latency_budget: -1\n")
    assert_one_line_error(cli(graph, "profile", "check", str(bad)), code=1, words=f"{bad}:4: publishers")


def test_user_mistakes_are_one_line_and_a_non_zero_exit(graph: Dict[str, str]) -> None:
    assert_one_line_error(cli(graph, "topic", "info", "/no_such_topic"), code=1, words="unknown topic /no_such_topic")
    assert_one_line_error(cli(graph, "topic", "latency", "/no_such_topic", "--count", "1"), code=1,
                          words="unknown topic")
    dead = _dead_master_env(graph)
    for args in (("topic", "info", "/no_such_topic"), ("graph", "--dot"), ("topic", "latency", TOPIC)):
        assert_one_line_error(cli(dead, *args), code=1, words="cannot reach the ROS master")
    # a topic DDS discovery has (the micros_rt nodes' DDS endpoints): its ROS 2 side, and the master's trouble in a
    # note, as topic list does when one side cannot be read
    cp = cli(dead, "topic", "info", TOPIC)
    assert cp.returncode == 0 and f"ROS 2 side (DDS rt/{TOPIC[1:]}" in cp.stdout, (cp.stdout, cp.stderr)
    assert "note: ROS 1 side not listed: cannot reach the ROS master" in cp.stderr, cp.stderr
    assert_one_line_error(cli(graph, "topic", "info"), code=2, words="usage: micros-rt topic info")
    assert_one_line_error(cli(graph, "profile", "check", "/no/such/file.yaml"), code=1, words="cannot read")
    assert_one_line_error(cli(graph, "topic", "nonsense"), code=2, words="unknown command")
    for help_args in (["--help"], ["topic", "-h"], ["topic", "info", "-h"], ["graph", "-h"], ["doctor", "-h"],
                      ["profile", "check", "-h"]):
        cp = cli(graph, *help_args)
        assert cp.returncode == 0 and cp.stdout.strip() and not cp.stderr, (help_args, cp.stderr)
