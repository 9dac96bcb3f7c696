"""micros_rt nodes in a ROS 1 graph with stock rospy nodes and tools: TCPROS both ways."""

from __future__ import annotations

import subprocess

import harness
from helpers import mrt, received, stock_listener, stock_talker, transports


def test_micros_rt_talker_heard_by_rostopic_echo(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    talker = spawn(mrt("talk", "--topic", "/echo_me", "--count", "400", "--rate", "20", "--prefix", "mrt"))
    talker.wait_for("ready", 30)
    cp = harness.rostopic(ros_master, "echo", "-n", "2", "/echo_me", timeout=30)
    lines = [ln for ln in cp.stdout.splitlines() if ln.startswith("data:")]
    assert len(lines) == 2, cp.stdout
    assert all("mrt " in ln for ln in lines), cp.stdout


def test_stock_talker_heard_by_micros_rt_listener(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/from_stock", "--duration", "20"))
    listener.wait_for("ready", 30)
    talker = spawn(stock_talker("--topic", "/from_stock", "--count", "30", "--rate", "30", "--prefix", "stock",
                                "--wait-subscribers", "1", "--linger", "1"))
    listener.wait_for_count("recv", 30, timeout=30)
    got = received(listener)
    assert got[:30] == [f"stock {i}" for i in range(30)]
    assert set(transports(listener)) == {"TCPROS"}
    talker.wait(30)


def test_micros_rt_talker_heard_by_stock_listener(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(stock_listener("--topic", "/to_stock", "--count", "20", "--duration", "30"))
    listener.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/to_stock", "--count", "20", "--rate", "30", "--wait-subscribers", "1",
              "--linger", "2"))
    events = listener.wait_for_count("recv", 20, timeout=30)
    assert [e["data"] for e in events[:20]] == [f"hello {i}" for i in range(20)]


def test_rostopic_pub_reaches_micros_rt_listener(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/typed_in", "--duration", "25"))
    listener.wait_for("ready", 30)
    harness.rostopic(ros_master, "pub", "-1", "/typed_in", "std_msgs/String", "data: from rostopic", timeout=30)
    ev = listener.wait_for("recv", 15)
    assert ev["data"] == "from rostopic"
    assert ev["transport"] == "TCPROS"


def test_rostopic_list_info_and_rosnode_see_micros_rt_node(ros_master: harness.RosMaster,
                                                          spawn: harness.Spawner) -> None:
    talker = spawn(mrt("talk", "--topic", "/visible", "--count", "400", "--rate", "20", "--node-name", "visible_talker"))
    talker.wait_for("ready", 30)
    assert "/visible" in harness.rostopic(ros_master, "list").stdout
    info = harness.rostopic(ros_master, "info", "/visible").stdout
    assert "std_msgs/String" in info and "/visible_talker" in info
    assert "/visible_talker" in harness.rosnode(ros_master, "list").stdout
    # rostopic hz never exits by itself: stop it with SIGINT after its start-up and a few reports
    hz = subprocess.run(["timeout", "-s", "INT", "10", harness.STOCK_PYTHON, harness.ROSTOPIC, "hz", "-w", "5",
                         "/visible"], env=ros_master.env, capture_output=True, text=True, timeout=40).stdout
    assert "average rate" in hz, hz


NAMES_SCRIPT = """
import sys
import micros_rt
from std_msgs.msg import String
micros_rt.init_node("namer")
nh, sub_nh, priv_nh = micros_rt.NodeHandle(), micros_rt.NodeHandle("arm"), micros_rt.NodeHandle("~")
pub = nh.advertise("chatter", String, 1)
names = [pub.resolved_name, nh.resolve_name("~priv"), sub_nh.resolve_name("joint"), priv_nh.resolve_name("p"),
         nh.resolve_name("/abs")]
sys.stdout.write(" ".join(names) + "\\n")  # one write: a log line of another thread cannot land inside it
sys.stdout.flush()
micros_rt.shutdown()
"""


def test_names_resolve_like_rospy(ros_master: harness.RosMaster) -> None:
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", NAMES_SCRIPT, "__ns:=robot1", "chatter:=talk"],
                        env=ros_master.env, capture_output=True, text=True, timeout=60)
    assert cp.returncode == 0, cp.stderr
    names = [line for line in cp.stdout.splitlines() if not line.startswith("[")]  # rospy's INFO lines go to stdout
    assert " ".join(names).split() == ["/robot1/talk", "/robot1/namer/priv", "/robot1/arm/joint", "/robot1/namer/p",
                                 "/abs"]
