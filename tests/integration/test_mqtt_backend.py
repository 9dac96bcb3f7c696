"""MQTT as a back end of micros_rt topics, chosen in the YAML profile: a publisher mirrored to the broker,
subscribers in another graph fed from it (transport MQTT, time filter enforced), a subscriber of the
publisher's own graph hearing each message once, JSON to mosquitto_sub, text from mosquitto_pub."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Dict

import harness
from helpers import mrt
from mqtt_broker import MosquittoBroker, write_params

N = 40


def fed_from_mqtt(peer: harness.Peer) -> Any:
    """Wait until the subscriber's MQTT subscription is made (logged right after it is sent)."""
    return peer.wait_for(lambda e: e.get("event") == "log" and "is fed from MQTT topic" in e.get("text", ""),
                         timeout=30)


def test_profile_rules_mirror_publishers_and_feed_subscribers(
        ros_master: harness.RosMaster, fresh_master: harness.RosMaster, spawn: harness.Spawner,
        tmp_path: Path) -> None:
    with MosquittoBroker(tmp_path / "broker") as broker:
        mqtt: Dict[str, Any] = {
            "broker": {"host": broker.host, "port": broker.port},
            "topics": {
                "/mb/*": {},                                        # glob, ros1 codec, MQTT topic mb/...
                "^/mb/json/.*$": {"codec": "json"},                 # regular expression
                "/mb/level": {"codec": "primitive", "direction": "in"},
            },
        }

        def profile(name: str, **sections: Any) -> Dict[str, str]:
            path = write_params(tmp_path / f"{name}.yaml", {"mqtt": mqtt, **sections})
            return {"MICROS_RT_QOS_PROFILE": str(path)}

        env_a = dict(ros_master.env, **profile("a", publishers={"/mb/chatter": {"msg_valid_period": 5.0}}))
        env_b = dict(fresh_master.env, **profile("b"))
        env_b_filtered = dict(fresh_master.env, **profile(
            "b_filtered", subscribers={"/mb/chatter": {"time_filter_duration": 0.5}}))

        same_graph = spawn(mrt("listen", "--topic", "/mb/chatter", "--duration", 90, "--node-name", "mb_a_listener"),
                           env_a, name="a_listener")
        other_graph = spawn(mrt("listen", "--topic", "/mb/chatter", "--duration", 90, "--exit-after", N,
                                "--node-name", "mb_b_listener"), env_b, name="b_listener")
        filtered = spawn(mrt("listen", "--topic", "/mb/chatter", "--duration", 90, "--node-name", "mb_b_filtered"),
                         env_b_filtered, name="b_filtered")
        level = spawn(mrt("listen", "--topic", "/mb/level", "--type", "std_msgs/Int32", "--duration", 90,
                          "--exit-after", 1, "--node-name", "mb_b_level"), env_b, name="b_level")
        json_sub = spawn(broker.sub_argv("mb/json/pose", count=3, timeout=60), name="json_sub")
        for peer in (same_graph, other_graph, filtered, level):
            fed_from_mqtt(peer)
        time.sleep(0.5)                                   # the broker has processed the SUBSCRIBEs

        talker = spawn(mrt("talk", "--topic", "/mb/chatter", "--count", N, "--rate", 20, "--wait-subscribers", 1,
                           "--node-name", "mb_talker"), env_a, name="talker")
        pose = {"header": {"frame_id": "base"}, "pose": {"position": {"x": 2.5}}}
        spawn(mrt("talk", "--topic", "/mb/json/pose", "--type", "geometry_msgs/PoseStamped", "--count", 10,
                  "--rate", 10, "--data-json", json.dumps(pose), "--node-name", "mb_pose"), env_a, name="pose")
        broker.pub("mb/level", "42", qos=1)

        got_b = other_graph.wait_for_count("recv", N, timeout=90)
        assert [e["data"] for e in got_b] == [f"hello {i}" for i in range(N)]
        assert {e["transport"] for e in got_b} == {"MQTT"}
        assert {e["callerid"] for e in got_b} == {"/mb_talker"}
        status = other_graph.wait_for("done", timeout=30)["transports"]
        assert "MQTT" in status.values(), status

        assert talker.wait(timeout=60) == 0
        got_a = same_graph.wait_for_count("recv", N, timeout=60)
        harness.wait_until(lambda: len(other_graph.events("recv")) >= N, 5)   # let late copies show up
        assert [e["data"] for e in same_graph.events("recv")] == [f"hello {i}" for i in range(N)]
        assert {e["transport"] for e in got_a} == {"SHM"}        # its own graph's copy over MQTT is dropped

        filtered_n = len(filtered.wait_for_count("recv", 2, timeout=30))
        assert 2 <= filtered_n <= N // 3, filtered_n              # 2 s of 20 Hz through a 0.5 s time filter

        assert level.wait_for("recv", timeout=30)["data"] == 42
        assert json_sub.wait(timeout=60) == 0
        docs = [e for e in json_sub.events() if "header" in e]
        assert docs and all(d["header"]["frame_id"] == "base" and d["pose"]["position"]["x"] == 2.5 for d in docs)
        print(f"graph B over MQTT: {len(got_b)} of {N} in order (transport MQTT, {status}); graph A: {len(got_a)} "
              f"of {N} once, over DDS; 0.5 s time filter on the MQTT link: {filtered_n} of {N}; mosquitto_pub 42 "
              f"-> Int32 42; JSON: {json.dumps({k: v for k, v in docs[0].items() if k != '_rx'})}")
