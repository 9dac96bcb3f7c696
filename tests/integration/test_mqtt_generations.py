"""Two ROS graphs bridged through a real mosquitto by a bridge writing mqtt_client 1.x and a bridge writing
2.x (issue 22): each reads the other's generation, stamped and unstamped, and ``~latencies/<topic>``
works on both sides. The type announcements on the broker are checked byte for byte: three strings from the
1.x bridge, a fourth one-byte ``stamped`` field from the 2.x one."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Dict, List

import harness
from helpers import mrt, stock_listener, stock_talker
from mqtt_broker import MOSQUITTO_SUB, MosquittoBroker, bridge_argv, write_params

from micros_rt.transports.mqtt import codec

N = 10


def startup_lines(bridge: harness.Peer) -> str:
    return "\n".join([e.get("line", "") for e in bridge.events("_raw")] + [bridge.stderr_tail(200)])


def test_1x_bridge_and_2x_bridge_read_each_other_with_latencies(
        ros_master: harness.RosMaster, fresh_master: harness.RosMaster, spawn: harness.Spawner,
        tmp_path: Path) -> None:
    graph_a, graph_b = ros_master.env, fresh_master.env
    qos1 = {"ros": {"queue_size": 100}, "mqtt": {"qos": 1}}
    with MosquittoBroker(tmp_path / "broker") as broker:
        broker_params = {"host": broker.host, "port": broker.port}
        # bridge A writes mqtt_client 1.x (flag byte), bridge B 2.x (no flag byte, stamped field)
        params_a = write_params(tmp_path / "a.yaml", {"broker": broker_params, "bridge": {
            "mqtt_client_version": 1,
            "ros2mqtt": [
                {"ros_topic": "/gen/a_text", "mqtt_topic": "gen/a2b_text", "inject_timestamp": True, "advanced": qos1},
                {"ros_topic": "/gen/a_pose", "mqtt_topic": "gen/a2b_pose", "advanced": qos1},
            ],
            "mqtt2ros": [
                {"mqtt_topic": "gen/b2a_text", "ros_topic": "/gen/text_from_b", "advanced": qos1},
                {"mqtt_topic": "gen/b2a_pose", "ros_topic": "/gen/pose_from_b", "advanced": qos1},
            ],
        }})
        params_b = write_params(tmp_path / "b.yaml", {"broker": broker_params, "bridge": {
            "mqtt_client_version": 2,       # fixed: unset, it would follow A's 1.x announcements (issue 37)
            "ros2mqtt": [
                {"ros_topic": "/gen/b_text", "mqtt_topic": "gen/b2a_text", "inject_timestamp": True, "advanced": qos1},
                {"ros_topic": "/gen/b_pose", "mqtt_topic": "gen/b2a_pose", "advanced": qos1},
            ],
            "mqtt2ros": [
                {"mqtt_topic": "gen/a2b_text", "ros_topic": "/gen/text_from_a", "advanced": qos1},
                {"mqtt_topic": "gen/a2b_pose", "ros_topic": "/gen/pose_from_a", "advanced": qos1},
            ],
        }})

        listeners: Dict[str, harness.Peer] = {}
        for graph, env, other in (("b", graph_b, "a"), ("a", graph_a, "b")):
            listeners[f"{graph}_text"] = spawn(
                mrt("listen", "--topic", f"/gen/text_from_{other}", "--type", "std_msgs/String", "--duration", 90,
                    "--exit-after", N, "--queue-size", 100, "--node-name", f"{graph}_text_rx"), env,
                name=f"{graph}_text_rx")
            listeners[f"{graph}_pose"] = spawn(
                stock_listener("--topic", f"/gen/pose_from_{other}", "--type", "geometry_msgs/PoseStamped",
                               "--count", N, "--duration", 90, "--node-name", f"{graph}_pose_rx"), env,
                name=f"{graph}_pose_rx")
            listeners[f"{graph}_latency"] = spawn(
                mrt("listen", "--topic", f"/bridge_{graph}/latencies/gen/text_from_{other}", "--type",
                    "std_msgs/Float64", "--duration", 90, "--exit-after", 3, "--node-name", f"{graph}_latency_rx"),
                env, name=f"{graph}_latency_rx")
        for peer in listeners.values():
            peer.wait_for("ready", timeout=30)
        bridge_a = spawn(bridge_argv(params_a, name="bridge_a"), graph_a, name="bridge_a")
        bridge_b = spawn(bridge_argv(params_b, name="bridge_b"), graph_b, name="bridge_b")

        talkers: List[harness.Peer] = []
        for graph, env in (("a", graph_a), ("b", graph_b)):
            talkers.append(spawn(stock_talker("--topic", f"/gen/{graph}_text", "--type", "std_msgs/String", "--count",
                                              N, "--rate", 10, "--wait-subscribers", 1, "--prefix", f"from {graph}",
                                              "--node-name", f"{graph}_text_tx"), env, name=f"{graph}_text_tx"))
            talkers.append(spawn(stock_talker("--topic", f"/gen/{graph}_pose", "--type", "geometry_msgs/PoseStamped",
                                              "--count", N, "--rate", 10, "--wait-subscribers", 1,
                                              "--node-name", f"{graph}_pose_tx"), env, name=f"{graph}_pose_tx"))

        # 1.x -> 2.x reader (graph B) and 2.x -> 1.x reader (graph A): every message, the first included
        texts_b = listeners["b_text"].wait_for_count("recv", N, timeout=90)
        texts_a = listeners["a_text"].wait_for_count("recv", N, timeout=90)
        assert [e["data"] for e in texts_b] == [f"from a {i}" for i in range(N)]
        assert [e["data"] for e in texts_a] == [f"from b {i}" for i in range(N)]
        for graph, other in (("b", "a"), ("a", "b")):
            try:
                received = listeners[f"{graph}_pose"].wait_for_count("recv", N, timeout=90)
            except AssertionError:  # which hop lost them: the talker, either bridge (its counters and log)
                print(f"talker: {talkers[1 if other == 'a' else 3].events()[-4:]}\n"
                      f"bridge_{other}: {bridge_a.events()[-6:] if other == 'a' else bridge_b.events()[-6:]}\n"
                      f"{(bridge_a if other == 'a' else bridge_b).stderr_tail(3000)}\n"
                      f"bridge_{graph}: {bridge_b.events()[-6:] if graph == 'b' else bridge_a.events()[-6:]}\n"
                      f"{(bridge_b if graph == 'b' else bridge_a).stderr_tail(3000)}")
                raise
            got = [e["msg"] for e in received]
            sent = [e["msg"] for e in talkers[1 if other == "a" else 3].wait_for_count("sent", N, timeout=30)]
            for msg in got + sent:
                msg["header"].pop("seq", None)   # the republishing node numbers Header.seq itself
            assert got == sent, f"PoseStamped {other} -> {graph}"

        # ~latencies/<topic> from the 1.x stamp (graph B) and from the 2.x stamp (graph A)
        latencies = {g: [e["data"] for e in listeners[f"{g}_latency"].wait_for_count("recv", 3, timeout=30)]
                     for g in ("a", "b")}
        assert all(0.0 < v < 5.0 for vs in latencies.values() for v in vs), latencies

        # on the broker: A's announcements are 1.x (three strings), B's are 2.x with stamped as configured
        out = subprocess.run([MOSQUITTO_SUB, *broker.client_args(), "-t", "mqtt_client/ros_msg_type/gen/#",
                              "-C", "4", "-W", "20", "-F", "%t %x"], capture_output=True, text=True, timeout=60)
        announced = {}
        for line in out.stdout.splitlines():
            topic, _, hexed = line.partition(" ")
            announced[topic.rpartition("ros_msg_type/")[2]] = codec.decode_msg_type(bytes.fromhex(hexed))
        assert {t: (a.name, a.stamped) for t, a in announced.items()} == {
            "gen/a2b_text": ("std_msgs/String", None), "gen/a2b_pose": ("geometry_msgs/PoseStamped", None),
            "gen/b2a_text": ("std_msgs/String", True), "gen/b2a_pose": ("geometry_msgs/PoseStamped", False),
        }, out.stderr

        assert "writing mqtt_client 1.x" in startup_lines(bridge_a)
        assert "writing mqtt_client 2.x" in startup_lines(bridge_b)
        assert bridge_a.alive() and bridge_b.alive()
        for talker in talkers:
            assert talker.wait(timeout=30) == 0
        print(f"1.x bridge -> 2.x bridge: {len(texts_b)} String (stamped) + {N} PoseStamped; 2.x -> 1.x: "
              f"{len(texts_a)} String (stamped) + {N} PoseStamped; latencies (s) A {latencies['a']}, "
              f"B {latencies['b']}; announcements {sorted((t, a.stamped) for t, a in announced.items())}")
