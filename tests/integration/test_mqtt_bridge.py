"""The mqtt_client-compatible bridge against a real mosquitto: JSON and primitive text to mosquitto_sub,
mosquitto_pub text to a micros_rt listener, the first message, bad input, the is_connected service."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

import harness
from helpers import mrt
from mqtt_broker import MosquittoBroker, bridge_argv, last_counters, write_params

from micros_rt.transports.mqtt import codec

@pytest.fixture
def broker(tmp_path: Path) -> Any:
    with MosquittoBroker(tmp_path / "broker") as b:
        yield b


def raw_lines(peer: harness.Peer) -> List[str]:
    return [e["line"] for e in peer.events("_raw")]


def wait_connected(bridge: harness.Peer, timeout: float = 30.0) -> None:
    harness.wait_until(lambda: int(last_counters(bridge).get("connects", 0)) >= 1, timeout,  # type: ignore[call-overload]
                       message=f"bridge never connected:\n{bridge.stderr_tail()}")


def publish_all(broker: MosquittoBroker, messages: List[Tuple[str, bytes, int, bool]], timeout: float = 30.0) -> None:
    """Publish (topic, payload, qos, retain) tuples in order from this process and wait for every ack."""
    client = paho.Client(CallbackAPIVersion.VERSION2, client_id="", protocol=paho.MQTTv311)
    client.connect(broker.host, broker.port)
    client.loop_start()
    try:
        infos = [client.publish(t, p, q, r) for t, p, q, r in messages]
        deadline = time.monotonic() + timeout
        for info in infos:
            info.wait_for_publish(max(0.1, deadline - time.monotonic()))
    finally:
        client.disconnect()
        client.loop_stop()


def test_talker_to_mosquitto_sub_as_json_and_text_and_mosquitto_pub_69_to_listener(
        ros_master: harness.RosMaster, spawn: harness.Spawner, broker: MosquittoBroker, tmp_path: Path) -> None:
    params = write_params(tmp_path / "params.yaml", {
        "broker": {"host": broker.host, "port": broker.port},
        "bridge": {
            "ros2mqtt": [
                {"ros_topic": "/mq1/pose", "mqtt_topic": "mq1/pose", "json": True},
                {"ros_topic": "/mq1/count", "mqtt_topic": "mq1/count", "primitive": True},
            ],
            "mqtt2ros": [{"mqtt_topic": "mq1/in", "ros_topic": "/mq1/in", "primitive": True}],
        },
    })
    bridge = spawn(bridge_argv(params, name="mq1_bridge"), name="bridge")
    wait_connected(bridge)
    sub_json = spawn(broker.sub_argv("mq1/pose", count=5, timeout=60), name="sub_json")
    sub_text = spawn(broker.sub_argv("mq1/count", count=5, timeout=60), name="sub_text")
    time.sleep(0.5)   # mosquitto_sub has subscribed (no retained messages here)
    pose = {"header": {"frame_id": "map", "stamp": {"secs": 12, "nsecs": 34}},
            "pose": {"position": {"x": 1.5, "y": -2.0, "z": 0.25}, "orientation": {"w": 1.0}}}
    spawn(mrt("talk", "--topic", "/mq1/pose", "--type", "geometry_msgs/PoseStamped", "--count", 20, "--rate", 20,
              "--wait-subscribers", 1, "--data-json", json.dumps(pose), "--node-name", "mq1_pose_talker"))
    spawn(mrt("talk", "--topic", "/mq1/count", "--type", "std_msgs/Int32", "--count", 20, "--rate", 20,
              "--wait-subscribers", 1, "--node-name", "mq1_count_talker"))

    assert sub_json.wait(timeout=60) == 0, sub_json.stderr_tail()
    # the harness parses JSON stdout lines itself (adding "_rx"): each is one message as JSON
    docs = [{k: v for k, v in e.items() if k != "_rx"} for e in sub_json.events() if "header" in e]
    assert len(docs) == 5
    for doc in docs:
        assert doc["header"]["frame_id"] == "map" and doc["header"]["stamp"] == {"secs": 12, "nsecs": 34}
        assert doc["pose"]["position"] == {"x": 1.5, "y": -2.0, "z": 0.25}
        assert doc["pose"]["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert sub_text.wait(timeout=60) == 0, sub_text.stderr_tail()
    texts = raw_lines(sub_text)
    assert len(texts) == 5 and all(t.isdigit() for t in texts)
    assert [int(t) for t in texts] == list(range(int(texts[0]), int(texts[0]) + 5)), texts
    print(f"mosquitto_sub JSON: {json.dumps(docs[0])}\nmosquitto_sub text: {texts}")

    listener = spawn(mrt("listen", "--topic", "/mq1/in", "--type", "std_msgs/Int32", "--duration", 60,
                         "--exit-after", 1, "--node-name", "mq1_listener"), name="listener")
    listener.wait_for("ready", timeout=30)
    broker.pub("mq1/in", "69")
    got = listener.wait_for("recv", timeout=30)
    assert got["data"] == 69
    print(f"mosquitto_pub -m 69 -> micros_rt listener: {got['data']} via {got['transport']}")


def test_first_message_bad_input_and_is_connected(
        ros_master: harness.RosMaster, spawn: harness.Spawner, broker: MosquittoBroker, tmp_path: Path) -> None:
    params = write_params(tmp_path / "params.yaml", {
        "broker": {"host": broker.host, "port": broker.port},
        "client": {"max_packet_size": 400},
        "bridge": {
            "mqtt2ros": [
                {"mqtt_topic": "mq2/data", "ros_topic": "/mq2/data", "advanced": {"mqtt": {"qos": 1},
                                                                                  "ros": {"queue_size": 100}}},
                {"mqtt_topic": "mq2/level", "ros_topic": "/mq2/level", "primitive": True,
                 "ros_type": "std_msgs/UInt8"},
            ],
            # and back out, as text: a message over client/max_packet_size is dropped and counted
            "ros2mqtt": [{"ros_topic": "/mq2/data", "mqtt_topic": "mq2/echo", "primitive": True,
                          "advanced": {"ros": {"queue_size": 100}}}],
        },
    })
    bridge = spawn(bridge_argv(params, name="mq2_bridge"), name="bridge")
    wait_connected(bridge)
    listener = spawn(mrt("listen", "--topic", "/mq2/data", "--type", "std_msgs/String", "--duration", 90,
                         "--node-name", "mq2_listener"), name="listener")
    listener.wait_for("ready", timeout=30)

    from std_msgs.msg import String
    import io

    def ros1(text: str) -> bytes:
        buf = io.BytesIO()
        String(data=text).serialize(buf)
        return codec.encode_ros_payload(buf.getvalue(), wire=codec.WireGeneration.V1)

    announcement = codec.encode_msg_type(codec.RosMsgType.of(String))
    # the data arrives before its type: mqtt_client drops it, this bridge holds it until the type comes
    publish_all(broker, [("mq2/data", ros1("first"), 1, False),
                         ("mqtt_client/ros_msg_type/mq2/data", announcement, 1, True)])
    first = listener.wait_for("recv", timeout=30)
    assert first["data"] == "first"
    harness.wait_until(lambda: any("'/mq2/data' (std_msgs/String) subscribed" in e.get("line", "")
                                   for e in bridge.events("_raw")), 30)
    # up to two lines: 'first' itself may still reach the echo topic late (the bridge's own subscriber of
    # /mq2/data delivers what it held until its DDS negotiation answered), the 1000-char one must not
    echo = spawn(broker.sub_argv("mq2/echo", count=2, timeout=10), name="echo")
    time.sleep(0.5)

    malformed = [b"", b"\x07not mqtt_client", b"\x01\x00", b"\x00\xff\xff\xff\x7fshort"]
    bad = [("mq2/data", malformed[i % len(malformed)], 1, False) for i in range(1000)]
    bad += [("mq2/level", b"300", 1, False), ("mq2/level", b"abc", 1, False)]
    big = [("mq2/data", ros1("x" * 1000), 1, False)]
    publish_all(broker, bad + big + [("mq2/data", ros1("after 1000 bad"), 1, False), ("mq2/level", b"7", 1, False)])
    after = listener.wait_for(lambda e: e.get("event") == "recv" and e.get("data") == "after 1000 bad", timeout=60)
    assert after["data"] == "after 1000 bad"

    def counted() -> bool:
        bad_input: Dict[str, int] = last_counters(bridge).get("bad_input", {})  # type: ignore[assignment]
        return bad_input.get("malformed") == 1000 and bad_input.get("unfit_text") == 2

    try:
        harness.wait_until(counted, 30)
    except AssertionError:
        raise AssertionError(f"counters: {last_counters(bridge)}") from None
    echo.wait(timeout=60)  # two lines, or the -W timeout with one
    lines = [e.get("line") for e in echo.events()]
    assert "after 1000 bad" in lines and set(lines) <= {"first", "after 1000 bad"}, lines  # 1000 chars: too large
    harness.wait_until(lambda: last_counters(bridge).get("dropped_too_large") == 1, 30)
    counters: Dict[str, Any] = last_counters(bridge)
    assert counters["delivered"]["/mq2/data"] == 3 and counters["delivered"]["/mq2/level"] == 1

    call = subprocess.run([harness.MICROS_RT_PYTHON, "-c", (
        "import rospy; from micros_rt.bridges.mqtt.bridge import is_connected_service_class as c; "
        "rospy.wait_for_service('/mq2_bridge/is_connected', 20); "
        "print(rospy.ServiceProxy('/mq2_bridge/is_connected', c())().connected)")],
        env=ros_master.env, capture_output=True, text=True, timeout=60)
    assert call.stdout.strip() == "True", call.stderr
    assert bridge.alive()
    bridge.stop()
    warnings = [line for line in bridge.stderr_tail(200).splitlines() if "does not decode" in line]
    assert len(warnings) == 1, warnings
    assert any("over client/max_packet_size (400 bytes)" in line for line in bridge.stderr_tail(200).splitlines())
    print(f"1000 malformed payloads: counted {counters['bad_input']}, one warning: {warnings[0]}\n"
          f"is_connected: {call.stdout.strip()}")


def test_primitive_texts_of_changing_kinds_retype_the_ros_topic_and_installed_types_are_logged_as_such(
        ros_master: harness.RosMaster, spawn: harness.Spawner, broker: MosquittoBroker, tmp_path: Path) -> None:
    """Issue 44: texts 42, abc, 1.5, True, 7 on one primitive MQTT topic: mqtt_client re-advertises the ROS
    topic as Int32, String, Float32, Bool, Int32 (True included); so does the bridge,
    counted in ``retyped``. A framed topic of an installed type is not logged as 'not installed here'."""
    params = write_params(tmp_path / "params.yaml", {
        "broker": {"host": broker.host, "port": broker.port},
        "bridge": {"mqtt2ros": [{"mqtt_topic": "mq4/kinds", "ros_topic": "/mq4/kinds", "primitive": True}],
                   "ros2mqtt": [{"ros_topic": "/mq4/chatter", "mqtt_topic": "mq4/chatter"}]},
    })
    bridge = spawn(bridge_argv(params, name="mq4_bridge"), name="bridge")
    wait_connected(bridge)
    talker = spawn([harness.STOCK_PYTHON, str(harness.PEERS_DIR / "stock_talker.py"), "--topic", "/mq4/chatter",
                    "--count", "1000", "--rate", "10", "--node-name", "mq4_talker"], name="talker")
    talker.wait_for("ready", 30)

    def topic_type() -> str:
        return str(dict(harness.master_call(ros_master, "getTopicTypes")).get("/mq4/kinds", ""))

    seen = []
    for text, kind in (("42", "std_msgs/Int32"), ("abc", "std_msgs/String"), ("1.5", "std_msgs/Float32"),
                       ("True", "std_msgs/Bool"), ("7", "std_msgs/Int32")):
        broker.pub("mq4/kinds", text)
        harness.wait_until(lambda: topic_type() == kind, 20, interval=0.1,
                           message=f"/mq4/kinds to be advertised as {kind} after the text {text!r}")
        seen.append(topic_type())
    counters = bridge.wait_for(lambda e: e.get("event") == "counters"
                               and e.get("delivered", {}).get("/mq4/kinds", 0) >= 5, 20)
    line = harness.wait_until(lambda: next((x for x in raw_lines(bridge) + bridge.stderr_tail(400).splitlines()
                                            if "'/mq4/chatter' (std_msgs/String" in x), ""), 20,
                              message="the bridge to log its subscription of /mq4/chatter")
    print(f"\nprimitive texts 42, abc, 1.5, True, 7 -> {seen}; counters {counters}\n{line}")
    assert counters["retyped"] == {"/mq4/kinds": 4} and counters["bad_input"] == {}
    assert "not installed" not in line and "bridged as its serialized bytes" in line
