"""The relay's ``ros2:`` section (issue 35, deliverable 3): stock ROS 1 nodes and ROS 2 nodes through
``micros-rt relay``, topics and services both ways, latched topics as transient_local both ways, ``/clock``.

Processes (all real, shared by the tests of this file): a rosmaster of its own; ``micros-rt relay`` with the
minimal configuration of the issue (plus a latched topic each way and ``/clock``);
tests/peers/stock_relay_peer.py, a stock rospy node (/usr/bin/python3, no micros_rt) that publishes ``/chatter``,
``/clock`` and the latched ``/ros1_latched``, serves ``/set_flag`` and subscribes to ``/ros2_chatter``;
tests/peers/ros2_relay_peer.py, an rclpy node (.venv-ros2, Fast DDS on loopback) that publishes ``/ros2_chatter``
and the transient_local ``/ros2_latched``, serves ``/ros2_trigger`` and subscribes to ``/chatter`` and ``/clock``;
tests/peers/dds_static_broadcasters.py, two static transform broadcasters as ROS 2 has them on the wire (``/tf_static``);
and the stock ``rostopic`` and ``rosservice`` tools and a stock tf2_ros listener. test_msgs/BasicTypes (``/r2_custom``,
``/r2_basic``, ``/ros1_basic``) has no ROS 1 package on this host: the relay builds it from the ROS 2 installation,
and the stock tools read it from the modules the relay writes.
"""

from __future__ import annotations

import concurrent.futures
import json
import re
import subprocess
import threading
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional

import pytest

import harness

pytestmark = pytest.mark.integration

CLI = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
ROSSERVICE = "/usr/bin/rosservice"

CONFIG = """\
graph: robot
ros2:
  export: {/chatter: {}, /set_flag: {}, /ros1_latched: {}, /clock: {}, /ros1_basic: {}}   # ROS 1 topic or service
  import: {/ros2_chatter: {}, /ros2_trigger: {}, /ros2_latched: {}, /r2_custom: {}, /r2_basic: {}, /tf_static: {}}
"""
#: the frames of /tf_static's two broadcasters
STATIC_FRAMES = ("base_link:laser", "base_link:camera")
T = 30.0   # generous bound on any one wait (the 2-core machine may be busy)


class Setup:
    def __init__(self, master: harness.RosMaster, relay: harness.Peer, stock: harness.Peer, ros2: harness.Peer,
                 stock_dir: Path, ros2_dir: Path, broadcasters: harness.Peer) -> None:
        self.master, self.relay, self.stock, self.ros2 = master, relay, stock, ros2
        self.broadcasters = broadcasters
        self.stock_dir, self.ros2_dir = stock_dir, ros2_dir
        #: the micros-rt tools' outputs (TOOLS), run in the background once the relay carries every entry: each
        #: mostly waits on DDS discovery, so they overlap the other tests instead of adding their seconds
        self.tools: "concurrent.futures.Future[List[subprocess.CompletedProcess[str]]]" = concurrent.futures.Future()

    def ros2_entry(self, direction: str, name: str, ready: Callable[[Dict[str, Any]], bool]) -> Dict[str, Any]:
        """The relay's counters of ``ros2:`` entry ``name`` once ``ready(counters)`` holds."""
        def match(event: Dict[str, Any]) -> bool:
            if event.get("event") != "stats":
                return False
            return any(e.get("direction") == direction and e.get("name") == name and ready(e)
                       for e in event.get("ros2", []))

        event = self.relay.wait_for(match, timeout=T)
        return next(e for e in event["ros2"] if e.get("direction") == direction and e.get("name") == name)


@pytest.fixture(scope="module")
def setup(dds_domain: int, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Setup]:
    work = tmp_path_factory.mktemp("relay_ros2")
    master = harness.RosMaster(workdir=work / "master", domain_id=dds_domain)
    master.start()
    peers: List[harness.Peer] = []
    try:
        config = work / "relay.yaml"
        config.write_text(CONFIG)
        stock_dir, ros2_dir = work / "stock", work / "ros2"
        stock_dir.mkdir()
        ros2_dir.mkdir()
        env = dict(master.env)
        # all three start at once: their start-up (imports, DDS discovery) overlaps
        relay = harness.Peer([CLI, "relay", "--config", str(config), "--json", "--stats-period", "0.3",
                              "--poll-period", "0.3"], env, name="relay")
        peers.append(relay)
        stock = harness.Peer([harness.STOCK_PYTHON, str(harness.PEERS_DIR / "stock_relay_peer.py"),
                              "--trigger-dir", str(stock_dir)], env, name="stock_peer")
        peers.append(stock)
        ros2 = harness.Peer([harness.ROS2_PYTHON, str(harness.PEERS_DIR / "ros2_relay_peer.py"),
                             "--trigger-dir", str(ros2_dir)], env, name="ros2_peer")
        peers.append(ros2)
        broadcasters = harness.Peer([str(harness.REPO_ROOT / ".venv" / "bin" / "python"),
                                     str(harness.PEERS_DIR / "dds_static_broadcasters.py"), "--frames",
                                     *STATIC_FRAMES], env, name="static_broadcasters")
        peers.append(broadcasters)
        for peer in peers:
            peer.wait_for("ready", timeout=T)
        setup = Setup(master, relay, stock, ros2, stock_dir, ros2_dir, broadcasters)
        tools = threading.Thread(target=_run_tools, args=(setup,), name="micros-rt tools", daemon=True)
        tools.start()
        yield setup
    finally:
        if "tools" in locals():
            tools.join(timeout=70)
        for peer in reversed(peers):
            peer.stop()
        master.cleanup()


def _tool(master: harness.RosMaster, tool: str, *args: str, timeout: float = T,
          env: Optional[Dict[str, str]] = None) -> str:
    cp = subprocess.run([harness.STOCK_PYTHON, tool, *args], env={**master.env, **(env or {})},
                        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    assert cp.returncode == 0, f"{Path(tool).name} {' '.join(args)} exited {cp.returncode}:\n{cp.stdout}\n{cp.stderr}"
    return cp.stdout


def test_topics_both_ways_and_the_stock_tools(setup: Setup) -> None:
    # ROS 1 -> ROS 2: the stock publisher's /chatter reaches the rclpy subscriber
    heard = setup.ros2.wait_for(lambda e: e.get("event") == "recv" and e.get("topic") == "/chatter", timeout=T)
    assert str(heard["data"]).startswith("ros1 ")
    # /clock is carried (rosgraph_msgs/Clock is ROS 2's too): the stock node's clock, 1000 s + n * 0.1 s
    tick = setup.ros2.wait_for("clock", timeout=T)
    assert tick["sec"] >= 1000 and tick["nanosec"] % 100_000_000 == 0, tick
    # ROS 2 -> ROS 1: the rclpy publisher's /ros2_chatter reaches the stock subscriber
    heard = setup.stock.wait_for(lambda e: e.get("event") == "recv" and e.get("topic") == "/ros2_chatter", timeout=T)
    assert str(heard["data"]).startswith("ros2 ")
    # the imported topic is in the ROS 1 graph, for the stock tools
    assert "/ros2_chatter" in _tool(setup.master, harness.ROSTOPIC, "list").split()
    info = _tool(setup.master, harness.ROSTOPIC, "info", "/ros2_chatter")
    assert "Type: std_msgs/String" in info and "/relay_robot" in info, info
    echoed = _tool(setup.master, harness.ROSTOPIC, "echo", "-n", "2", "/ros2_chatter")
    assert echoed.count('data: "ros2 ') == 2, echoed
    out = setup.ros2_entry("export", "/chatter", lambda e: e.get("sent", 0) >= 5)
    assert out["kind"] == "topic" and out["as"] == "/chatter" and out["latch"] is False
    assert out["looped"] == 0 and out["dropped_queue_full"] == 0, out
    incoming = setup.ros2_entry("import", "/ros2_chatter", lambda e: e.get("published", 0) >= 5)
    assert incoming["kind"] == "topic" and incoming["refused"] == 0 and incoming["dropped_queue_full"] == 0, incoming
    # no loops, no doubles: the relay does not publish its export back in ROS 1, nor its import on DDS (ROS 2 sees
    # one publisher of each: the relay's writer of /chatter, the rclpy node of /ros2_chatter), and each message
    # arrives once
    publishers = harness.system_state(setup.master)["publishers"].get("/chatter", [])
    assert [p for p in publishers if p.startswith("/relay")] == [], publishers
    seen = setup.ros2.wait_for(lambda e: e.get("event") == "heard" and e.get("n", 0) >= 5, timeout=T)
    assert seen["ros2_chatter_publishers"] == 1 and seen["chatter_publishers"] == 1, seen
    for peer, topic in ((setup.ros2, "/chatter"), (setup.stock, "/ros2_chatter")):
        data = [e["data"] for e in peer.events("recv") if e.get("topic") == topic]
        assert len(data) == len(set(data)), (topic, data)


def test_services_both_ways(setup: Setup) -> None:
    # a stock `rosservice call` in ROS 1 reaches the rclpy server through the relay, once the relay offers it (when
    # its ROS 2 helper has found the server: about 2 s after the relay first sees it)
    master = harness.xmlrpc_proxy(setup.master.uri)
    harness.wait_until(lambda: list(master.lookupService("/test", "/ros2_trigger"))[0] == 1, T,  # type: ignore[arg-type]
                       message="the relay offering /ros2_trigger in ROS 1")
    answer = _tool(setup.master, ROSSERVICE, "call", "/ros2_trigger")
    assert "success: True" in answer and "triggered" in answer, answer
    setup.ros2.wait_for(lambda e: e.get("event") == "served" and e.get("name") == "/ros2_trigger", timeout=T)
    # an rclpy client in ROS 2 reaches the stock rospy server through the relay
    (setup.ros2_dir / "call.tmp").write_text(json.dumps({"name": "/set_flag", "count": 5, "data": True}))
    (setup.ros2_dir / "call.tmp").rename(setup.ros2_dir / "call")
    called = setup.ros2.wait_for("called", timeout=T)
    assert called["ok"] == 5, called
    assert called["last"]["success"] is True and "got True" in called["last"]["message"], called
    assert setup.stock.wait_for_count("served", 5, timeout=T)
    out = setup.ros2_entry("export", "/set_flag", lambda e: e.get("calls", 0) >= 5)
    assert out["kind"] == "service" and out["failed"] == 0 and out["type"] == "std_srvs/SetBool", out
    incoming = setup.ros2_entry("import", "/ros2_trigger", lambda e: e.get("calls", 0) >= 1)
    assert incoming["kind"] == "service" and incoming["failed"] == 0 and incoming["type"] == "std_srvs/Trigger"


def test_latched_late_joiners_both_ways(setup: Setup) -> None:
    # A second latched ROS 1 publisher of the topic, as /tf_static has one per static transform broadcaster: a late
    # ROS 1 subscriber gets each publisher's last message, and so must a late ROS 2 one (a single relay writer
    # keeping the topic's last message would give it one of the two: ros1_bridge's special case for /tf_static).
    second = subprocess.Popen([harness.STOCK_PYTHON, harness.ROSTOPIC, "pub", "-l", "/ros1_latched", "std_msgs/String",
                               "data: 'latched by rostopic'"], env=setup.master.env, stdin=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # the relay holds each latched message before the late subscribers come
        out = setup.ros2_entry("export", "/ros1_latched", lambda e: len(e.get("latched_publishers", [])) >= 2)
        assert out["latch"] is True and out["sent"] >= 2, out
        incoming = setup.ros2_entry("import", "/ros2_latched", lambda e: e.get("published", 0) >= 1)
        assert incoming["latch"] is True, incoming
        (setup.ros2_dir / "late").touch()
        (setup.stock_dir / "late").touch()
        lates = setup.ros2.wait_for_count("late", 2, timeout=T)
        # the other way, the rclpy node's two transient_local writers of /ros2_latched: a late stock subscriber
        # gets each one's message, as it would from two latched ROS 1 publishers
        lates1 = setup.stock.wait_for_count("late", 2, timeout=T)
    finally:
        second.terminate()
        second.wait(10)
    assert sorted(e["data"] for e in lates) == sorted(
        [f"ros1 latched {setup.stock.events('ready')[0]['pid']}", "latched by rostopic"]), lates
    late2 = max(lates, key=lambda e: e["after_ms"])
    ros2_pid = setup.ros2.events("ready")[0]["pid"]
    both = sorted([f"ros2 latched {ros2_pid}", f"ros2 latched 2 {ros2_pid}"])
    assert sorted(e["data"] for e in lates1) == both, lates1
    late1 = max(lates1, key=lambda e: e["after_ms"])
    print(f"late joiners: ROS 2 subscriber of the ROS 1 latched topic {late2['after_ms']:.0f} ms, "
          f"stock ROS 1 subscriber of the ROS 2 transient_local topic {late1['after_ms']:.0f} ms")
    assert late2["after_ms"] < 2000 and late1["after_ms"] < 2000, (late2, late1)
    # and stock `rostopic echo -n 2` of the imported latched topic gets both writers' messages at once
    echoed = _tool(setup.master, harness.ROSTOPIC, "echo", "-n", "2", "/ros2_latched", timeout=10.0)
    print(f"late `rostopic echo -n 2 /ros2_latched` (2 transient_local ROS 2 writers):\n{echoed}")
    assert sorted(re.findall(r'data: "(ros2 latched[^"]*)"', echoed)) == both, echoed


def test_every_static_transform_reaches_a_late_ros1_tf_listener(setup: Setup) -> None:
    """Two static transform broadcasters on ROS 2's side of /tf_static: a stock tf2_ros listener that starts after
    the relay has both gets both frames (ROS 1 keeps one latched message per publisher)."""
    incoming = setup.ros2_entry("import", "/tf_static", lambda e: e.get("published", 0) >= len(STATIC_FRAMES))
    assert incoming["latch"] is True and incoming["refused"] == 0, incoming
    script = ("import json, sys, time, rospy, tf2_ros\n"
              "rospy.init_node('late_tf_listener', anonymous=True, disable_signals=True)\n"
              "buf = tf2_ros.Buffer()\nlistener = tf2_ros.TransformListener(buf)\n"
              "frames = sys.argv[1:]\ndeadline = time.monotonic() + 15\n"
              "def have(f): return buf.can_transform('base_link', f, rospy.Time(0))\n"
              "while time.monotonic() < deadline and not all(have(f) for f in frames): time.sleep(0.05)\n"
              "print(json.dumps({f: buf.lookup_transform('base_link', f, rospy.Time(0)).transform.translation.x "
              "for f in frames if have(f)}))\n")
    children = [pair.split(":")[1] for pair in STATIC_FRAMES]
    out = _tool(setup.master, "-c", script, *children)
    got = json.loads(out.strip().splitlines()[-1])
    print(f"late tf2_ros listener of /tf_static (2 ROS 2 static broadcasters): {got}")
    assert got == {child: float(i + 1) for i, child in enumerate(children)}, got


def _yaml_fields(echoed: str) -> Dict[str, Any]:
    import yaml

    return {k: v for k, v in yaml.safe_load(echoed.split("---")[0]).items()}


#: what the rclpy peer publishes on /r2_custom (tests/peers/ros2_relay_peer.py BASIC), as ROS 1 reads it: the same
#: bits, ROS 1's ``byte`` being int8 where ROS 2's is an octet (200 is -56)
BASIC = {"bool_value": True, "byte_value": 200, "char_value": 100, "float32_value": 1.5, "float64_value": -2.25e300,
         "int8_value": -128, "uint8_value": 255, "int16_value": -32768, "uint16_value": 65535,
         "int32_value": -2 ** 31, "uint32_value": 2 ** 32 - 1, "int64_value": -2 ** 63, "uint64_value": 2 ** 64 - 1}
BASIC_ROS1 = {**BASIC, "byte_value": 200 - 256}


def _types_path(setup: Setup) -> Dict[str, str]:
    """Where the relay writes the modules of the types it built (``$ROS_HOME/micros_rt/ros1_types``): on the stock
    tools' PYTHONPATH, as a user does with the path the relay's log names."""
    return {"PYTHONPATH": str(Path(setup.master.env["ROS_HOME"]) / "micros_rt" / "ros1_types")}


def test_a_ros2_only_type_reaches_stock_rostopic_echo_with_every_field(setup: Setup) -> None:
    incoming = setup.ros2_entry("import", "/r2_custom", lambda e: e.get("published", 0) >= 1)
    assert incoming["kind"] == "topic" and incoming["bad_input"] == 0, incoming
    assert incoming["type_source"] == "ROS 2 definition", incoming
    info = _tool(setup.master, harness.ROSTOPIC, "info", "/r2_custom")
    assert "Type: test_msgs/BasicTypes" in info, info
    echoed = _tool(setup.master, harness.ROSTOPIC, "echo", "-n", "1", "/r2_custom", env=_types_path(setup))
    print(f"stock `rostopic echo -n 1 /r2_custom` (test_msgs/BasicTypes from rclpy, no ROS 1 package):\n{echoed}")
    assert _yaml_fields(echoed) == BASIC_ROS1, echoed   # stock rospy connected: the md5s agree


def test_services_of_a_ros2_only_type_both_ways(setup: Setup) -> None:
    # ROS 1 -> ROS 2: stock `rosservice call` of the rclpy server, once the relay offers it
    master = harness.xmlrpc_proxy(setup.master.uri)
    harness.wait_until(lambda: list(master.lookupService("/test", "/r2_basic"))[0] == 1, T,  # type: ignore[arg-type]
                       message="the relay offering /r2_basic in ROS 1")
    request = {**BASIC_ROS1, "string_value": "héllo"}
    answer = _tool(setup.master, ROSSERVICE, "call", "/r2_basic", json.dumps(request), env=_types_path(setup))
    assert _yaml_fields(answer) == request, answer
    # ROS 2 -> ROS 1: an rclpy client of the stock rospy server, whose class is built at run time (same md5)
    (setup.ros2_dir / "call_basic.tmp").write_text(json.dumps({"name": "/ros1_basic",
                                                               "fields": {**BASIC, "string_value": "wörld"}}))
    (setup.ros2_dir / "call_basic.tmp").rename(setup.ros2_dir / "call_basic")
    called = setup.ros2.wait_for("called_basic", timeout=T)
    assert called.get("fields") == {**BASIC, "string_value": "wörld"}, called
    for direction, name in (("import", "/r2_basic"), ("export", "/ros1_basic")):
        entry = setup.ros2_entry(direction, name, lambda e: e.get("calls", 0) >= 1)
        assert entry["failed"] == 0 and entry["type"] == "test_msgs/BasicTypes", entry


# a topic only ROS 2 has: docs/migration.md's step 3 (tests/integration/test_migration.py). --wait 4: each tool is a
# new DDS participant, which learns the others' endpoints ~1.1 s after meeting them when idle (the default listens
# 1.5 s); four tools started at once beside the relay and the peers are not idle
TOOLS = (["topic", "info", "--json", "--wait", "4", "/chatter"], ["topic", "info", "--wait", "4", "/ros2_chatter"],
         ["service", "list", "--json", "--wait", "4"], ["graph", "--dot", "--wait", "4"])


def _run_tools(setup: Setup) -> None:
    """Once the relay carries each entry, run TOOLS side by side; their results (or the failure) in setup.tools."""
    try:
        setup.ros2_entry("export", "/chatter", lambda e: e.get("sent", 0) >= 1)
        setup.ros2_entry("import", "/ros2_chatter", lambda e: e.get("published", 0) >= 1)
        setup.ros2_entry("import", "/ros2_trigger", lambda e: e.get("kind") == "service")
        setup.ros2_entry("export", "/set_flag", lambda e: e.get("kind") == "service")
        procs = [subprocess.Popen([CLI, *argv], env=dict(setup.master.env), stdin=subprocess.DEVNULL,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for argv in TOOLS]
        done = []
        for argv, proc in zip(TOOLS, procs):
            try:
                out, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                for p in procs:
                    p.kill()
                raise AssertionError(f"micros-rt {' '.join(argv)} did not finish in 60 s") from None
            done.append(subprocess.CompletedProcess(argv, proc.returncode, out, err))
        setup.tools.set_result(done)
    except BaseException as exc:  # the test that reads the results reports it
        setup.tools.set_exception(exc)


def test_the_tools_see_both_worlds_and_what_the_relay_carries(setup: Setup) -> None:
    # issue 43, deliverable 4: topic info of either world, service list across both, graph with ROS 2 nodes
    results = setup.tools.result(timeout=2 * T)
    for cp in results:
        assert cp.returncode == 0 and "Traceback" not in cp.stderr, (cp.args, cp.returncode, cp.stdout, cp.stderr)
    out, into, services, dot = results
    rclpy_node = f"/ros2_relay_peer_{setup.ros2.events('ready')[0]['pid']}"
    stock_node = f"/stock_relay_peer_{setup.stock.events('ready')[0]['pid']}"
    # /chatter: a stock ROS 1 publisher; the relay carries it to ROS 2, where the rclpy node reads the relay's writer
    data = json.loads(out.stdout)
    assert data["side"] == "ROS 1+2" and data["ros2_types"] == ["std_msgs/msg/String"], data
    relay = [ep for ep in data["subscribers"] if ep["node"] == "/relay_robot"][0]
    assert relay["ros2_carriage"][0].startswith("carried to ROS 2 as /chatter by relay node /relay_robot: sent "), relay
    assert relay["ros2_carriage"][0].endswith(f"; read in ROS 2 by {rclpy_node}"), relay
    assert [(w["node"], w["kind"]) for w in data["ros2_writers"]] == [("/relay_robot", "relay")], data["ros2_writers"]
    assert [(r["node"], r["kind"], r["qos"]) for r in data["ros2_readers"]] == [(rclpy_node, "ROS 2", "reliable, volatile")]
    assert [(l["publisher"], l["subscriber"], l["matched"]) for l in data["dds_links"]] == [
        ("/relay_robot", rclpy_node, True)], data["dds_links"]
    # /ros2_chatter: where it comes from (the rclpy writer), and the relay publishing it in ROS 1 for the stock node
    text = into.stdout
    assert "Side: ROS 1+2" in text, text
    assert (f"carried from ROS 2 (its /ros2_chatter) into ROS 1 by relay node /relay_robot: published" in text
            and f"; written in ROS 2 by {rclpy_node}" in text), text
    assert f" * {rclpy_node}  [ROS 2] std_msgs/msg/String; reliable, volatile" in text, text
    assert f" * /relay_robot -> {stock_node}: TCPROS" in text, text
    # services of both worlds, with types, sides and the relay's carriage
    rows = {s["name"]: s for s in json.loads(services.stdout)["services"]}
    assert (rows["/set_flag"]["side"], rows["/set_flag"]["ros1_type"], rows["/set_flag"]["ros1_servers"],
            rows["/set_flag"]["ros2_servers"]) == ("ROS 1+2", "std_srvs/SetBool", [stock_node],
                                                   ["/relay_robot (relay, its ROS 2 helper)"]), rows["/set_flag"]
    assert rows["/set_flag"]["carried"] == ["relay /relay_robot: ROS 1 /set_flag -> ROS 2 /set_flag"], rows["/set_flag"]
    assert (rows["/ros2_trigger"]["side"], rows["/ros2_trigger"]["ros1_type"], rows["/ros2_trigger"]["ros1_servers"],
            rows["/ros2_trigger"]["ros2_servers"]) == ("ROS 1+2", "std_srvs/Trigger", ["/relay_robot (relay)"],
                                                       [rclpy_node]), rows["/ros2_trigger"]
    assert not [n for n in rows if n.endswith(("/get_loggers", "/set_parameters"))], sorted(rows)  # node plumbing: -a
    # the graph: the rclpy node drawn, the DDS link from the relay's writer to it, the relay's carriage both ways
    assert f'"r2:{rclpy_node}" [label="{rclpy_node}\\nROS 2 node"' in dot.stdout, dot.stdout
    assert f'"t:/chatter" -> "r2:{rclpy_node}" [label="DDS from /relay_robot"' in dot.stdout, dot.stdout
    assert '"n:/relay_robot" -> "t:/chatter" [label="relay to ROS 2\\n(ROS 1 /chatter)"' in dot.stdout, dot.stdout
    assert '"t:/ros2_chatter" -> "n:/relay_robot" [label="relay from ROS 2\\n' in dot.stdout, dot.stdout
    assert f'"r2:{rclpy_node}" -> "r2service:/ros2_trigger" [label="server"' in dot.stdout, dot.stdout
