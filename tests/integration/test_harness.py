"""The harness itself, on real parts: rosmaster, stock rospy peers, rostopic, rclpy peers, loopback DDS."""


import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from harness import (  # noqa: E402
    RosApiError,
    RosMaster,
    Spawner,
    eth0_tx_packets,
    lookup_node,
    master_call,
    node_call,
    ros2_peer_argv,
    rostopic,
    stock_listener_argv,
    stock_talker_argv,
    system_state,
    wait_until,
)

pytestmark = pytest.mark.integration

# eth0 was silent on this machine while idle (0 packets in 12 s); allow a few unrelated packets.
ETH0_SLACK = 5


@pytest.fixture
def eth0_quiet() -> Iterator[None]:
    """Fails the test if more than ETH0_SLACK packets left eth0 while it ran."""
    before = eth0_tx_packets()
    yield
    after = eth0_tx_packets()
    if before is not None and after is not None:
        assert after - before < ETH0_SLACK, f"{after - before} packets left eth0 during the test"


def test_master_answers(ros_master: RosMaster, dds_domain: int) -> None:
    assert master_call(ros_master, "getPid") == ros_master.pid
    pubs, subs, srvs = master_call(ros_master, "getSystemState")
    assert isinstance(pubs, list) and isinstance(subs, list) and isinstance(srvs, list)
    assert master_call(ros_master, "getUri") == ros_master.uri
    with pytest.raises(RosApiError) as e:
        lookup_node(ros_master, "/no_such_node")
    assert e.value.code == -1
    env = ros_master.env
    assert env["ROS_MASTER_URI"] == ros_master.uri and env["ROS_IP"] == "127.0.0.1"
    assert env["ROS_DOMAIN_ID"] == str(dds_domain) == os.environ["ROS_DOMAIN_ID"]
    assert env["CYCLONEDDS_URI"].startswith("file://") and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert 1 <= dds_domain <= 200


def test_stock_talker_heard_by_stock_listener(ros_master: RosMaster, spawn: Spawner, eth0_quiet: None) -> None:
    topic = "/harness/chatter"
    listener = spawn(stock_listener_argv("--topic", topic, "--count", "5", "--node-name", "h_listener"))
    listener.wait_for("ready", 20)
    talker = spawn(stock_talker_argv("--topic", topic, "--count", "5", "--rate", "100",
                                     "--wait-subscribers", "1", "--node-name", "h_talker", "--prefix", "hi"))
    ready = talker.wait_for("ready", 20)
    assert ready["node"] == "/h_talker"

    # The master sees both, and the talker's slave API reports the link.
    state = system_state(ros_master)
    assert "/h_talker" in state["publishers"][topic]
    assert "/h_listener" in state["subscribers"][topic]
    talker_uri = lookup_node(ros_master, "/h_talker")
    assert talker_uri == ready["uri"]

    recv = listener.wait_for_count("recv", 5, 20)
    assert [e["data"] for e in recv] == [f"hi {i}" for i in range(5)]
    assert recv[0]["connection_header"]["callerid"] == "/h_talker"
    assert recv[0]["connection_header"]["transport"] == "TCPROS"
    assert listener.wait(20) == 0
    assert talker.wait(20) == 0
    # Both unregistered on exit.
    wait_until(lambda: topic not in system_state(ros_master)["publishers"], 10, message="talker unregistered")


def test_bus_info_and_stamped_type(ros_master: RosMaster, spawn: Spawner) -> None:
    topic = "/harness/pose"
    listener = spawn(stock_listener_argv("--topic", topic, "--type", "geometry_msgs/PoseStamped",
                                         "--duration", "30", "--node-name", "h_pose_listener"))
    listener.wait_for("ready", 20)
    talker = spawn(stock_talker_argv("--topic", topic, "--type", "geometry_msgs/PoseStamped", "--count", "3",
                                     "--wait-subscribers", "1", "--linger", "20", "--node-name", "h_pose_talker"))
    uri = talker.wait_for("ready", 20)["uri"]
    ev = listener.wait_for("recv", 20)
    assert set(ev["stamp"]) == {"secs", "nsecs"} and ev["stamp"]["secs"] > 0
    assert ev["msg"]["pose"]["orientation"]["w"] == 1.0
    # getBusInfo: [connectionId, destinationId, direction, transport, topic, connected, info]
    bus = node_call(uri, "getBusInfo")
    assert any(b[2] == "o" and b[3] == "TCPROS" and b[4] == topic for b in bus), bus
    bus = node_call(lookup_node(ros_master, "/h_pose_listener"), "getBusInfo")
    assert any(b[1] == uri and b[2] == "i" and b[4] == topic for b in bus), bus


def test_rostopic_echo_hears_stock_talker(ros_master: RosMaster, spawn: Spawner) -> None:
    topic = "/harness/echo"
    talker = spawn(stock_talker_argv("--topic", topic, "--count", "0", "--rate", "20", "--duration", "30",
                                     "--prefix", "echo"))
    talker.wait_for("ready", 20)
    out = rostopic(ros_master, "echo", "-n", "1", topic, timeout=20).stdout
    assert 'data: "echo ' in out, out
    info = rostopic(ros_master, "info", topic).stdout
    assert "std_msgs/String" in info


def test_fresh_master_restart_same_port(fresh_master: RosMaster, spawn: Spawner) -> None:
    port, pid = fresh_master.port, fresh_master.pid
    talker = spawn(stock_talker_argv("--topic", "/harness/restart", "--count", "0", "--rate", "5",
                                     "--duration", "30"), fresh_master.env)
    talker.wait_for("ready", 20)
    assert "/harness/restart" in system_state(fresh_master)["publishers"]
    fresh_master.restart()
    assert fresh_master.port == port and fresh_master.pid != pid
    assert master_call(fresh_master, "getPid") == fresh_master.pid
    # A new master knows nothing of the old graph (rospy does not re-register by itself).
    assert "/harness/restart" not in system_state(fresh_master)["publishers"]


def test_rclpy_pair_on_loopback(ros_master: RosMaster, spawn: Spawner, eth0_quiet: None) -> None:
    env = ros_master.env  # ROS_DOMAIN_ID + Fast DDS loopback profile
    listener = spawn(ros2_peer_argv("listen", "--topic", "/harness/ros2", "--count", "5"), env)
    listener.wait_for("ready", 20)
    talker = spawn(ros2_peer_argv("talk", "--topic", "/harness/ros2", "--count", "5", "--rate", "50",
                                  "--wait-subscribers", "1", "--prefix", "r2"), env)
    recv = listener.wait_for_count("recv", 5, 20)
    assert [e["data"] for e in recv] == [f"r2 {i}" for i in range(5)]
    assert talker.wait(20) == 0 and listener.wait(20) == 0


def test_rclpy_info_reports_qos(ros_master: RosMaster, spawn: Spawner) -> None:
    env = ros_master.env
    talker = spawn(ros2_peer_argv("talk", "--topic", "/harness/qos", "--count", "0", "--rate", "5",
                                  "--reliability", "best_effort", "--durability", "transient_local",
                                  "--duration", "30"), env)
    talker.wait_for("ready", 20)
    info = spawn(ros2_peer_argv("info", "--topic", "/harness/qos", "--wait", "15", "--min-publishers", "1"), env)
    ev = info.wait_for("info", 20)
    assert len(ev["publishers"]) == 1, ev
    qos = ev["publishers"][0]["qos"]
    assert qos["reliability"] == "best_effort" and qos["durability"] == "transient_local"


def test_cyclone_loopback_config_reaches_rclpy(ros_master: RosMaster, dds_domain: int, spawn: Spawner,
                                               eth0_quiet: None) -> None:
    """In-process Cyclone (tests/cyclonedds_loopback.xml via CYCLONEDDS_URI) and an rclpy peer interoperate."""
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    assert os.environ["CYCLONEDDS_URI"].endswith("cyclonedds_loopback.xml")

    @dataclass
    class RosString(IdlStruct, typename="std_msgs::msg::dds_::String_"):
        data: str

    listener = spawn(ros2_peer_argv("listen", "--topic", "/harness/cyclone", "--count", "1"), ros_master.env)
    listener.wait_for("ready", 20)
    dp: Any = DomainParticipant(dds_domain)
    try:
        writer: Any = DataWriter(dp, Topic(dp, "rt/harness/cyclone", RosString))
        wait_until(lambda: len(writer.get_matched_subscriptions()) > 0, 20, message="rclpy reader matched")
        writer.write(RosString(data="from cyclone"))
        ev = listener.wait_for("recv", 20)
        assert ev["data"] == "from cyclone"
    finally:
        del dp
