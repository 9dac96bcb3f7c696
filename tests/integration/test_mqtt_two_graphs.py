"""Two ROS graphs (two masters) bridged both ways through mosquitto, arbitrary types field for field,
the first message delivered, latencies on ~latencies/<topic>."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path
from typing import Any, Dict

import harness
from helpers import mrt, stock_listener, stock_talker
from mqtt_broker import MosquittoBroker, bridge_argv, write_params

N = 15


def _mrt_peer() -> Any:
    spec = importlib.util.spec_from_file_location("mrt_peer_fns", harness.PEERS_DIR / "mrt_peer.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def without_seq(msg: Dict[str, Any]) -> Dict[str, Any]:
    """The republishing node numbers Header.seq itself (as every ROS 1 publisher does)."""
    out = copy.deepcopy(msg)
    out["header"].pop("seq", None)
    return out


def test_two_graphs_both_ways_image_and_pose_field_for_field(
        ros_master: harness.RosMaster, fresh_master: harness.RosMaster, spawn: harness.Spawner,
        tmp_path: Path) -> None:
    graph_a, graph_b = ros_master.env, fresh_master.env
    qos1 = {"ros": {"queue_size": 100}, "mqtt": {"qos": 1}}
    with MosquittoBroker(tmp_path / "broker") as broker:
        broker_params = {"host": broker.host, "port": broker.port}
        params_a = write_params(tmp_path / "a.yaml", {"broker": broker_params, "bridge": {
            "ros2mqtt": [
                {"ros_topic": "/g/image", "mqtt_topic": "g/image", "inject_timestamp": True, "advanced": qos1},
                {"ros_topic": "/g/pose", "mqtt_topic": "g/pose", "advanced": qos1},
            ],
            "mqtt2ros": [{"mqtt_topic": "g/back", "ros_topic": "/g/back", "advanced": qos1}],
        }})
        params_b = write_params(tmp_path / "b.yaml", {"broker": broker_params, "bridge": {
            "ros2mqtt": [{"ros_topic": "/g/reply", "mqtt_topic": "g/back", "advanced": qos1}],
            "mqtt2ros": [
                {"mqtt_topic": "g/image", "ros_topic": "/g/image", "advanced": qos1},
                {"mqtt_topic": "g/pose", "ros_topic": "/g/pose", "advanced": qos1},
            ],
        }})
        # listeners first, so that the bridges' new publishers find them (the first message must arrive)
        image_rx = spawn(mrt("listen", "--topic", "/g/image", "--type", "sensor_msgs/Image", "--full-msg",
                             "--duration", 90, "--exit-after", N, "--queue-size", 100, "--node-name", "b_image"),
                         graph_b, name="b_image")
        pose_rx = spawn(stock_listener("--topic", "/g/pose", "--type", "geometry_msgs/PoseStamped", "--count", N,
                                       "--duration", 90, "--node-name", "b_pose"), graph_b, name="b_pose")
        latency_rx = spawn(mrt("listen", "--topic", "/bridge_b/latencies/g/image", "--type", "std_msgs/Float64",
                               "--duration", 90, "--exit-after", 5, "--node-name", "b_latency"), graph_b,
                           name="b_latency")
        back_rx = spawn(mrt("listen", "--topic", "/g/back", "--type", "std_msgs/String", "--duration", 90,
                            "--exit-after", N, "--node-name", "a_back"), graph_a, name="a_back")
        for peer in (image_rx, pose_rx, latency_rx, back_rx):
            peer.wait_for("ready", timeout=30)
        spawn(bridge_argv(params_a, name="bridge_a"), graph_a, name="bridge_a")
        spawn(bridge_argv(params_b, name="bridge_b"), graph_b, name="bridge_b")

        image = {"height": 48, "width": 64, "encoding": "rgb8", "is_bigendian": 0, "step": 192,
                 "header": {"frame_id": "camera {i}", "stamp": {"secs": 1700000000, "nsecs": 5}},
                 "data": {"$bytes": {"len": 48 * 192, "seed": 5}}}
        image_tx = spawn(mrt("talk", "--topic", "/g/image", "--type", "sensor_msgs/Image", "--count", N,
                             "--rate", 10, "--wait-subscribers", 1, "--data-json", json.dumps(image),
                             "--node-name", "a_image"), graph_a, name="a_image")
        pose_tx = spawn(stock_talker("--topic", "/g/pose", "--type", "geometry_msgs/PoseStamped", "--count", N,
                                     "--rate", 10, "--wait-subscribers", 1, "--node-name", "a_pose"),
                        graph_a, name="a_pose")
        reply_tx = spawn(stock_talker("--topic", "/g/reply", "--type", "std_msgs/String", "--count", N,
                                      "--rate", 10, "--wait-subscribers", 1, "--prefix", "from graph B",
                                      "--node-name", "b_reply"), graph_b, name="b_reply")

        images = image_rx.wait_for_count("recv", N, timeout=90)
        poses = pose_rx.wait_for_count("recv", N, timeout=90)
        backs = back_rx.wait_for_count("recv", N, timeout=90)

        peer_fns = _mrt_peer()
        from sensor_msgs.msg import Image

        expected_images = [peer_fns.full_dict(peer_fns.set_fields(Image(), image, i)) for i in range(N)]
        assert [without_seq(e["msg"]) for e in images] == [without_seq(x) for x in expected_images]
        assert images[0]["msg"]["header"]["frame_id"] == "camera 0"          # the first message
        sent_poses = pose_tx.wait_for_count("sent", N, timeout=30)
        assert [without_seq(e["msg"]) for e in poses] == [without_seq(e["msg"]) for e in sent_poses]
        assert [e["data"] for e in backs] == [f"from graph B {i}" for i in range(N)]
        assert reply_tx.wait(timeout=30) == 0 and image_tx.wait(timeout=30) == 0

        latencies = [e["data"] for e in latency_rx.wait_for_count("recv", 5, timeout=30)]
        assert all(0.0 < v < 5.0 for v in latencies), latencies
        print(f"graph A -> B: {N} sensor_msgs/Image 64x48 rgb8 and {N} geometry_msgs/PoseStamped field for field "
              f"(first: {images[0]['msg']['header']['frame_id']!r}); graph B -> A: {N} std_msgs/String; "
              f"latencies (s): {[round(v, 4) for v in latencies]}")


def test_type_installed_on_neither_side(ros_master: harness.RosMaster, fresh_master: harness.RosMaster,
                                        spawn: harness.Spawner, tmp_path: Path) -> None:
    """robot_extra_msgs/Reading exists only in the talker's and listener's code (genpy.dynamic): bridge A
    takes its bytes and connection header, bridge B builds the class from the announced definition."""
    peer = [harness.STOCK_PYTHON, str(harness.PEERS_DIR / "mqtt_dynamic_peer.py")]
    n = 10
    with MosquittoBroker(tmp_path / "broker") as broker:
        broker_params = {"host": broker.host, "port": broker.port}
        qos1 = {"ros": {"queue_size": 100}, "mqtt": {"qos": 1}}
        # the generation set: with no announcing peer (B only reads) A would hold its first 10 s (issue 44, tested
        # in test_mqtt_late_peer.py); this test is about the type
        params_a = write_params(tmp_path / "a.yaml", {"broker": broker_params, "bridge": {
            "mqtt_client_version": 2, "ros2mqtt": [
                {"ros_topic": "/extra/reading", "mqtt_topic": "extra/reading", "advanced": qos1}]}})
        params_b = write_params(tmp_path / "b.yaml", {"broker": broker_params, "bridge": {"mqtt2ros": [
            {"mqtt_topic": "extra/reading", "ros_topic": "/extra/reading", "advanced": qos1}]}})
        graph_b = fresh_master.env
        listener = spawn([*peer, "listen", "--duration", "90"], graph_b, name="dyn_listener")
        listener.wait_for("ready", timeout=30)
        spawn(bridge_argv(params_a, name="dyn_bridge_a"), ros_master.env, name="dyn_bridge_a")
        spawn(bridge_argv(params_b, name="dyn_bridge_b"), graph_b, name="dyn_bridge_b")
        talker = spawn([*peer, "talk", "--count", str(n)], ros_master.env, name="dyn_talker")
        md5 = talker.wait_for("ready", timeout=30)["md5"]
        got = listener.wait_for_count("recv", n, timeout=90)
        assert [(e["name"], e["values"], e["level"], e["frame_id"]) for e in got] == [
            (f"reading {i}", [float(i), i + 0.5], i, "battery") for i in range(n)]
        assert {(e["type"], e["md5"]) for e in got} == {("robot_extra_msgs/Reading", md5)}
        print(f"robot_extra_msgs/Reading (installed nowhere) graph A -> B: {len(got)} of {n}, md5 {md5}")
