"""Issue 37, MQTT half, against a real mosquitto: the retained type announcement is on the broker after the
broker comes up mid-stream and after each restart (a fresh subscriber can decode the topic), and the
bridge writes each topic in the generation its peers announce on the broker (the real mqtt_client 1.1.0's
and 2.3.0's bytes, from tests/fixtures/mqtt_client/), the setting staying an override."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any, Dict, List, Tuple, cast

import pytest
from std_msgs.msg import String

import harness
from helpers import stock_talker
from mqtt_broker import MOSQUITTO_SUB, MosquittoBroker, bridge_argv, last_counters, write_params

from micros_rt.transports.mqtt import codec

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "mqtt_client"


def fixture(name: str) -> Dict[str, Any]:
    """A fixture of the real mqtt_client's bytes (its version and commit inside)."""
    data: Dict[str, Any] = json.loads((FIXTURES / name).read_text())
    return data


REAL_110 = fixture("mqtt_client-1.1.0-f9b53da.json")
REAL_230 = fixture("mqtt_client-2.3.0-0649f99.json")


def captured(real: Dict[str, Any], mqtt_topic: str) -> Tuple[bytes, bytes]:
    """(announcement, payload) the real program put on the broker for one of its topics."""
    m = next(m for m in real["messages"] if m["mqtt_topic"] == mqtt_topic)
    return bytes.fromhex(m["announcement_hex"]), bytes.fromhex(m["payload_hex"])


def retained(broker: MosquittoBroker, topic: str, timeout: int = 10) -> bytes:
    """What a fresh subscriber gets at once on ``topic`` (the retained message); fails when nothing is."""
    out = subprocess.run([MOSQUITTO_SUB, *broker.client_args(), "-t", topic, "-C", "1", "-W", str(timeout), "-F",
                          "%x", "--retained-only"], capture_output=True, text=True, timeout=timeout + 30)
    assert out.returncode == 0 and out.stdout.strip(), (
        f"no retained message on '{topic}' for a fresh subscriber (mosquitto_sub exit {out.returncode}: "
        f"{out.stderr.strip()})")
    return bytes.fromhex(out.stdout.strip())


def next_payloads(broker: MosquittoBroker, topic: str, n: int, timeout: int = 20) -> List[bytes]:
    out = subprocess.run([MOSQUITTO_SUB, *broker.client_args(), "-t", topic, "-C", str(n), "-W", str(timeout),
                          "-F", "%x", "-R"], capture_output=True, text=True, timeout=timeout + 30)
    lines = out.stdout.split()
    assert len(lines) == n, f"{len(lines)} of {n} messages on '{topic}': {out.stderr.strip()}"
    return [bytes.fromhex(line) for line in lines]


def counter(bridge: harness.Peer, kind: str, ros_topic: str) -> int:
    """A per-topic counter (``sent``, ``delivered``) of the bridge's newest counters line."""
    per_topic = cast(Dict[str, int], last_counters(bridge).get(kind) or {})
    return int(per_topic.get(ros_topic, 0))


def sent(bridge: harness.Peer, ros_topic: str) -> int:
    return counter(bridge, "sent", ros_topic)


def test_announcement_is_on_the_broker_after_it_comes_up_mid_stream_and_after_each_restart(
        ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    broker = MosquittoBroker(tmp_path / "broker")          # not started: the stream begins first
    params = write_params(tmp_path / "params.yaml", {"broker": {"host": broker.host, "port": broker.port}, "bridge": {
        "ros2mqtt": [{"ros_topic": "/ann/chatter", "mqtt_topic": "bh/micros"}]}})
    bridge = spawn(bridge_argv(params, name="ann_bridge", counters=0.2), name="ann_bridge")
    spawn(stock_talker("--topic", "/ann/chatter", "--type", "std_msgs/String", "--count", 0, "--rate", 20,
                       "--duration", 240, "--prefix", "stream", "--node-name", "ann_talker"), name="ann_talker")
    harness.wait_until(lambda: int(last_counters(bridge).get("dropped_disconnected", 0)) >= 10, 60,  # type: ignore
                       message=f"the bridge never took the stream:\n{bridge.stderr_tail()}")
    seen: List[str] = []
    try:
        for connects in (1, 2, 3):
            if connects == 1:
                broker.start()                             # first connect, mid-stream
            else:
                broker.restart()                           # retained messages are gone with the old broker
            harness.wait_until(lambda: int(last_counters(bridge).get("connects", 0)) >= connects, 60,  # type: ignore
                               message=f"no connect {connects}:\n{bridge.stderr_tail()}")
            base = sent(bridge, "/ann/chatter")
            harness.wait_until(lambda: sent(bridge, "/ann/chatter") >= base + 10, 30,
                               message="data did not flow after connecting")
            announcement = codec.decode_msg_type(retained(broker, "mqtt_client/ros_msg_type/bh/micros"))
            assert (announcement.name, announcement.md5, announcement.stamped) == (
                "std_msgs/String", String._md5sum, False)         # 2.x (no peer on the broker), not stamped
            for payload in next_payloads(broker, "bh/micros", 2):  # and the data decodes in the form it gives
                _, body = codec.decode_ros_payload(payload, stamped=announcement.stamped)
                text = String().deserialize(bytes(body)).data
                assert text.startswith("stream "), payload.hex()
                seen.append(text)
        assert bridge.alive()
    finally:
        broker.stop()
    print(f"announcement on the broker after the first connect and 2 restarts, mid-stream; payloads read with it: "
          f"{seen}; counters {last_counters(bridge)}")


@pytest.mark.parametrize("real, setting, expect", [
    (REAL_110, None, codec.WireGeneration.V1),     # a 1.1.0 peer: written back in 1.x (2.x would abort it)
    (REAL_230, None, codec.WireGeneration.V2),     # a 2.3.0 peer: 2.x
    (REAL_110, 2, codec.WireGeneration.V2),        # bridge/mqtt_client_version overrides the peers
], ids=["peer-1.1.0", "peer-2.3.0", "override-2-with-1.1.0-peer"])
def test_bridge_writes_in_the_generation_the_peer_announces(
        ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path, real: Dict[str, Any],
        setting: Any, expect: codec.WireGeneration) -> None:
    with MosquittoBroker(tmp_path / "broker") as broker:
        # the real client's own topic as it leaves it on the broker: its retained announcement (captured bytes)
        peer_announcement, peer_payload = captured(real, "capture/string")
        publish_raw(broker, "mqtt_client/ros_msg_type/peer/status", peer_announcement, retain=True)
        bridge_cfg: Dict[str, Any] = {
            "ros2mqtt": [{"ros_topic": "/gen/text", "mqtt_topic": "gen/text"}],
            "mqtt2ros": [{"mqtt_topic": "peer/status", "ros_topic": "/gen/peer_status"}]}
        if setting is not None:
            bridge_cfg["mqtt_client_version"] = setting
        params = write_params(tmp_path / "params.yaml", {"broker": {"host": broker.host, "port": broker.port},
                                                         "bridge": bridge_cfg})
        bridge = spawn(bridge_argv(params, name="gen_bridge", counters=0.2), name="gen_bridge")
        sub = subprocess.Popen([MOSQUITTO_SUB, *broker.client_args(), "-t", "gen/text", "-C", "1", "-W", "60",
                                "-F", "%x"], stdout=subprocess.PIPE, text=True)
        try:
            spawn(stock_talker("--topic", "/gen/text", "--type", "std_msgs/String", "--count", 0, "--rate", 5,
                               "--duration", 120, "--prefix", "gen", "--node-name", "gen_talker"), name="gen_talker")
            out, _ = sub.communicate(timeout=90)
        finally:
            if sub.poll() is None:
                sub.kill()
        payload = bytes.fromhex(out.strip())
        written = codec.decode_msg_type(retained(broker, "mqtt_client/ros_msg_type/gen/text"))
        assert written.wire is expect, (written, bridge.stderr_tail())
        body = codec.decode_ros_payload(payload, stamped=written.stamped)[1].tobytes()
        text = String().deserialize(body).data
        assert text.startswith("gen "), payload.hex()
        # the real program's framing in that generation: 1.1.0 a 00 flag byte, 2.3.0 none
        assert payload == codec.encode_ros_payload(body, wire=expect)
        assert payload[:len(payload) - len(body)] == (b"\x00" if expect is codec.WireGeneration.V1 else b"")
        assert peer_payload[:len(peer_payload) - 6] == (b"\x00" if real is REAL_110 else b"")   # 'hi': 6 bytes
        # the peer's own topic is read in its generation too (the captured data payload, via the broker)
        publish_raw(broker, "peer/status", peer_payload, retain=False)
        harness.wait_until(lambda: counter(bridge, "delivered", "/gen/peer_status") >= 1, 30,
                           message=f"the peer's payload was not delivered:\n{bridge.stderr_tail()}")
        assert last_counters(bridge).get("bad_input") == {} and bridge.alive()
        print(f"peer {real['version']} ({real['commit'][:7]}), setting {setting}: bridge wrote {expect.label} "
              f"(announcement {'three strings' if written.stamped is None else 'with stamped'}, payload "
              f"{payload.hex()})")


def publish_raw(broker: MosquittoBroker, topic: str, payload: bytes, *, retain: bool) -> None:
    """Publish bytes at QoS 1 (as the real client does with qos 1) and wait for the broker's ack."""
    import paho.mqtt.client as paho
    from paho.mqtt.enums import CallbackAPIVersion

    client = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv311)
    client.connect(broker.host, broker.port)
    client.loop_start()
    try:
        client.publish(topic, payload, 1, retain).wait_for_publish(30)
    finally:
        client.disconnect()
        client.loop_stop()
