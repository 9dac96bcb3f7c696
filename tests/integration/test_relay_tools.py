"""``micros-rt topic info`` and ``micros-rt graph`` show relayed links as such (issue 21, deliverable 5).

Two robots, each its own rosmaster on loopback, this run's DDS domain. Robot A: a stock rospy talker on
/chatter, a stock rospy listener of /chatter (an ordinary subscriber), and A's relay exporting /chatter (HIGH,
max_rate 50) and /status (LOW): two priorities, so /chatter is carried by the child process
``/relay_robot_a_high``. Robot B: B's relay importing /robot_a/chatter and a stock listener of it. The tools
run as subprocesses with each robot's ROS_MASTER_URI and must mark the relay's subscription in A as "relayed
out" and the relay's publication in B as "relayed in", and leave the ordinary nodes unmarked.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List, Tuple

import harness
from helpers import stock_listener, stock_talker
from test_cli_tools import cli
from test_relay import relay, robots, _stats_with  # noqa: F401  (robots: the two-master fixture)

from micros_rt.cli._graphinfo import probe_node

RELAY_A = """\
graph: robot_a
export:
  /chatter: {transport_priority: HIGH, max_rate: 50}
  /status: {transport_priority: LOW}
"""
RELAY_B = """\
graph: robot_b
import:
  /robot_a/chatter: {}
"""
TALKER, PLAIN, LISTENER_B = "/talker_a", "/plain_listener_a", "/listener_b"
RELAY_A_FIRST, RELAY_A_HIGH, RELAY_B_NODE = "/relay_robot_a", "/relay_robot_a_high", "/relay_robot_b"


def info(env: Dict[str, str], topic: str) -> Dict[str, Any]:
    cp = cli(env, "topic", "info", "--json", topic)
    assert cp.returncode == 0, cp.stderr
    data: Dict[str, Any] = json.loads(cp.stdout)
    return data


def by_node(endpoints: List[Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    return {ep["node"]: ep for ep in endpoints}



def _at(lines: List[str], prefix: str) -> int:
    """The index of the first of ``lines`` that starts with ``prefix``."""
    return next(i for i, line in enumerate(lines) if line.startswith(prefix))


def _assert_marked(lines: List[str], endpoint: str, link: str, marked: str) -> None:
    """``topic info``'s text: the line under ``endpoint`` starts with ``marked`` (then its counters), and the
    link's lines under ``link`` carry the marking without them."""
    at = _at(lines, endpoint)
    assert lines[at + 1].strip().startswith(marked), lines[at + 1]
    at = _at(lines, link)
    assert marked.rsplit("; ", 1)[0] in [line.strip() for line in lines[at + 1:at + 6]], lines[at:at + 6]

def test_topic_info_and_graph_mark_relayed_links(robots: Tuple[harness.RosMaster, harness.RosMaster],
                                                 spawn: harness.Spawner, tmp_path: Path) -> None:
    a, b = robots
    (tmp_path / "a.yaml").write_text(RELAY_A)
    (tmp_path / "b.yaml").write_text(RELAY_B)
    spawn(stock_talker("--topic", "/chatter", "--rate", 20, "--count", 0, "--duration", 150,
                       "--node-name", TALKER[1:]), env=a.env, name="talker_a")
    plain = spawn(stock_listener("--topic", "/chatter", "--duration", 150, "--node-name", PLAIN[1:]), env=a.env)
    relay_a = spawn(relay(tmp_path / "a.yaml"), env=a.env, name="relay_a")
    relay_b = spawn(relay(tmp_path / "b.yaml"), env=b.env, name="relay_b")
    listener_b = spawn(stock_listener("--topic", "/robot_a/chatter", "--duration", 150,
                                      "--node-name", LISTENER_B[1:]), env=b.env)
    _stats_with(relay_a, "exports", "/chatter")
    _stats_with(relay_b, "imports", "/robot_a/chatter")
    plain.wait_for("recv", 60)
    listener_b.wait_for_count("recv", 5, timeout=60)   # the whole chain carries messages

    # robot A: the relay's subscriber of /chatter is marked "relayed out", the stock listener is not
    seen: List[Dict[str, Any]] = [{}]

    def a_linked() -> bool:
        seen[0] = info(a.env, "/chatter")
        links = {(l["publisher"], l["subscriber"]) for l in seen[0]["links"]}
        return {(TALKER, RELAY_A_HIGH), (TALKER, PLAIN)} <= links
    harness.wait_until(a_linked, 60, interval=0.5, message="both links of /chatter in A")
    subs = by_node(seen[0]["subscribers"])
    out = subs[RELAY_A_HIGH]["relay"]
    assert (out["direction"], out["outside"], out["protocol"], out["transport_priority"], out["max_rate"]) == \
        ("out", "/robot_a/chatter", "DDS", "HIGH", 50), out
    assert (out["relay_node"], out["relay"], out["graph"]) == (RELAY_A_HIGH, RELAY_A_FIRST, "robot_a"), out
    assert out["counters"]["sent"] > 0 and out["counters"]["received"] >= out["counters"]["sent"], out
    assert "relay" not in subs[PLAIN] and "relay" not in by_node(seen[0]["publishers"])[TALKER]
    links = {(l["publisher"], l["subscriber"]): l for l in seen[0]["links"]}
    assert [m["direction"] for m in links[(TALKER, RELAY_A_HIGH)]["relayed"]] == ["out"]
    assert "relayed" not in links[(TALKER, PLAIN)], links[(TALKER, PLAIN)]

    cp = cli(a.env, "topic", "info", "/chatter")
    assert cp.returncode == 0, cp.stderr
    text = cp.stdout
    print(f"\n--- micros-rt topic info /chatter (robot A)\n{text}")
    marked = (f"relayed out as /robot_a/chatter (DDS, HIGH, reliable, max_rate 50 Hz) by relay node "
              f"{RELAY_A_HIGH} (a process of relay {RELAY_A_FIRST})")
    lines = text.splitlines()
    _assert_marked(lines, f" * {RELAY_A_HIGH} (", f" * {TALKER} -> {RELAY_A_HIGH}: TCPROS", marked + "; sent ")
    plain_at = _at(lines, f" * {PLAIN} (")
    assert "relayed" not in lines[plain_at + 1], lines[plain_at + 1]
    at = _at(lines, f" * {TALKER} -> {PLAIN}: TCPROS")
    assert not any("relayed" in line for line in lines[at:at + 4]), lines[at:at + 4]

    # the first process names its children (its own microsRtInfo)
    first = probe_node(RELAY_A_FIRST, harness.master_call(a, "lookupNode", RELAY_A_FIRST))
    section = first.relay()
    assert section is not None and section["children"] == [RELAY_A_HIGH, "/relay_robot_a_low"], first.info
    assert section["exports"] == [] and section["parent"] is None

    # robot B: the relay's publisher of /robot_a/chatter is marked "relayed in", the stock listener is not
    def b_linked() -> bool:
        seen[0] = info(b.env, "/robot_a/chatter")
        pubs = by_node(seen[0]["publishers"])
        return (any(l["subscriber"] == LISTENER_B for l in seen[0]["links"]) and RELAY_B_NODE in pubs
                and bool(pubs[RELAY_B_NODE].get("relay", {}).get("exporters")))
    harness.wait_until(b_linked, 60, interval=0.5, message="B's relay linked to B's listener, exporter seen")
    inbound = by_node(seen[0]["publishers"])[RELAY_B_NODE]["relay"]
    assert (inbound["direction"], inbound["origin"], inbound["outside"], inbound["exporters"]) == \
        ("in", "robot_a", "/robot_a/chatter", [RELAY_A_HIGH]), inbound
    assert inbound["counters"]["published"] > 0, inbound
    assert "relay" not in by_node(seen[0]["subscribers"])[LISTENER_B]
    cp = cli(b.env, "topic", "info", "/robot_a/chatter")
    assert cp.returncode == 0, cp.stderr
    print(f"\n--- micros-rt topic info /robot_a/chatter (robot B)\n{cp.stdout}")
    marked = (f"relayed in from graph robot_a (outside topic /robot_a/chatter, exported by {RELAY_A_HIGH}) by "
              f"relay node {RELAY_B_NODE}")
    lines = cp.stdout.splitlines()
    _assert_marked(lines, f" * {RELAY_B_NODE} (", f" * {RELAY_B_NODE} -> {LISTENER_B}: TCPROS",
                   marked + "; published ")
    at = _at(lines, f" * {LISTENER_B} (")
    assert "relayed" not in lines[at + 1], lines[at + 1]

    # micros-rt graph --dot: relays as relays, their edges to and from the outside topic
    cp = cli(a.env, "graph", "--dot")
    assert cp.returncode == 0, cp.stderr
    dot_a = cp.stdout
    print(f"\n--- micros-rt graph --dot (robot A)\n{dot_a}")
    assert (f'"n:{RELAY_A_HIGH}" [label="{RELAY_A_HIGH}\\nrelay, graph robot_a\\nprocess of {RELAY_A_FIRST}", '
            f'shape=hexagon') in dot_a
    assert '"o:/robot_a/chatter" [label="outside: /robot_a/chatter\\nto other graphs", shape=box' in dot_a
    assert f'"n:{RELAY_A_HIGH}" -> "o:/robot_a/chatter" [label="relay out\\nDDS HIGH\\nmax_rate 50 Hz"' in dot_a
    assert (f'"t:/chatter" -> "n:{RELAY_A_HIGH}" [label="TCPROS from {TALKER}\\nreliable\\n'
            f'relayed out as /robot_a/chatter"') in dot_a
    assert f'"n:{PLAIN}" [label="{PLAIN}\\nstock", shape=ellipse' in dot_a
    assert f'"t:/chatter" -> "n:{PLAIN}" [label="TCPROS from {TALKER}", ' in dot_a   # unmarked
    cp = cli(b.env, "graph", "--dot")
    assert cp.returncode == 0, cp.stderr
    dot_b = cp.stdout
    assert f'"n:{RELAY_B_NODE}" [label="{RELAY_B_NODE}\\nrelay, graph robot_b", shape=hexagon' in dot_b
    assert '"o:/robot_a/chatter" [label="outside: /robot_a/chatter\\nfrom graph robot_a"' in dot_b
    assert (f'"o:/robot_a/chatter" -> "n:{RELAY_B_NODE}" [label="relay in\\nfrom graph robot_a\\n'
            f'as /robot_a/chatter"') in dot_b
    assert f'"n:{RELAY_B_NODE}" -> "t:/robot_a/chatter" [label="reliable, NORMAL\\nrelayed in from graph robot_a"' \
        in dot_b
    assert f'"n:{LISTENER_B}" [label="{LISTENER_B}\\nstock", shape=ellipse' in dot_b
