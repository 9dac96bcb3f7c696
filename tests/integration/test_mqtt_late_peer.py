"""Issue 44: a default bridge (no mqtt_client_version) writes before any mqtt_client peer is on the broker; a
1.1.0 peer joins later as a reader of the bridge's topic and announces its own topic later still (the real
1.1.0's captured bytes, tests/fixtures/mqtt_client/). What the bridge wrote meanwhile must not be misread: the
1.1.0 reads every payload's first byte as its flag (a 2.x payload's first byte is a length byte, so it would
drop 9 bytes and republish the rest), so the bridge holds a topic's messages until a peer's generation is
known, then writes them in it. ``~is_connected`` then has the 1.x type (mqtt_client/IsConnected)."""

from __future__ import annotations

import subprocess
import time
import threading
from pathlib import Path
from typing import Any, List

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion
from std_msgs.msg import String

import harness
from helpers import stock_talker
from mqtt_broker import MosquittoBroker, bridge_argv, last_counters, write_params
from test_mqtt_announcements import REAL_110, captured, counter, publish_raw

from micros_rt.transports.mqtt import codec


def read_as_1x(payload: bytes) -> str:
    """What a 1.1.0 reader makes of a payload (its flag byte, then the String), or '' when it misreads it."""
    try:
        stamp, body = codec.decode_ros_payload(payload, stamped=None)
        raw = body.tobytes()
        msg = String().deserialize(raw)
        return str(msg.data) if stamp is None and len(raw) == 4 + len(msg.data.encode()) else ""
    except Exception:
        return ""


def test_a_1x_peer_joining_a_default_bridge_later_reads_nothing_corrupted(
        ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    with MosquittoBroker(tmp_path / "broker") as broker:
        params = write_params(tmp_path / "params.yaml", {"broker": {"host": broker.host, "port": broker.port},
                                                         "bridge": {"ros2mqtt": [{"ros_topic": "/late/chatter",
                                                                                  "mqtt_topic": "late/chatter"}]}})
        bridge = spawn(bridge_argv(params, name="late_bridge", counters=0.2), name="late_bridge")
        talker = spawn(stock_talker("--topic", "/late/chatter", "--type", "std_msgs/String", "--count", 0,
                                    "--rate", 20, "--duration", 120, "--prefix", "late", "--node-name", "late_talker"),
                       name="late_talker")
        # the bridge has taken messages (held: no peer has announced a generation)
        harness.wait_until(lambda: talker.count("sent") >= 20, 60, message="the talker to send 20")
        harness.wait_until(lambda: counter(bridge, "held", "late/chatter") >= 10 or sent(bridge) >= 10, 30,
                           message="the bridge to take 10 messages")
        # the 1.1.0 joins: it reads the bridge's topic (no announcement: a reader says nothing) ...
        got: List[bytes] = []
        lock = threading.Lock()
        peer = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv311)

        def on_message(client: Any, userdata: Any, message: Any) -> None:
            with lock:
                got.append(bytes(message.payload))
        peer.on_message = on_message
        peer.connect(broker.host, broker.port)
        peer.loop_start()
        try:
            peer.subscribe("late/chatter", 1)
            harness.wait_until(lambda: talker.count("sent") >= 40, 30, message="the talker to send 20 more")
            # ... then it publishes on its own topic, announcing (retained) in 1.1.0's three-string form
            announcement, payload = captured(REAL_110, "capture/string")
            publish_raw(broker, "mqtt_client/ros_msg_type/peer110/status", announcement, retain=True)
            publish_raw(broker, "peer110/status", payload, retain=False)
            harness.wait_until(lambda: len(got) >= 60, 60, message="60 payloads at the 1.1.0 reader")
        finally:
            peer.loop_stop()
            peer.disconnect()
        service_type = subprocess.run([harness.STOCK_PYTHON, "/usr/bin/rosservice", "type",
                                       "/late_bridge/is_connected"], env=ros_master.env, capture_output=True,
                                      text=True, timeout=30)
    with lock:
        texts = [read_as_1x(p) for p in got]
    corrupted = sum(1 for t in texts if not t)
    counters = last_counters(bridge)
    print(f"\n1.1.0 reader joined a default bridge later: {len(got)} payloads, {corrupted} misread as 1.x; first "
          f"{texts[:3]}; counters held {counters.get('held')} sent {counters.get('sent')}; ~is_connected "
          f"{service_type.stdout.strip()!r}")
    assert corrupted == 0, [p.hex() for p, t in zip(got, texts) if not t][:3]
    numbers = [int(t.split()[-1]) for t in texts]
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers))), numbers   # in order, none lost
    assert service_type.stdout.strip() == "mqtt_client/IsConnected", service_type.stdout + service_type.stderr
    assert bridge.alive()


def sent(bridge: harness.Peer) -> int:
    return counter(bridge, "sent", "/late/chatter")


def test_a_peers_repeated_announcements_do_not_reach_the_bridge(
        ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    """mqtt_client publishes its type announcement with every message. A peer streaming 500 msg/s on an
    unrelated topic and on a topic the bridge reads: once the bridge knows the peers' generation and its
    topic's type, it no longer receives the repetitions (it scans the retained announcements every 2 s), so
    it handles about one MQTT message per data message, not three (issue 44: 8.6-9.1 % of a core idle)."""
    from std_msgs.msg import Int32

    with MosquittoBroker(tmp_path / "broker") as broker:
        params = write_params(tmp_path / "params.yaml", {"broker": {"host": broker.host, "port": broker.port},
                                                         "bridge": {
            "ros2mqtt": [{"ros_topic": "/rep/nobody", "mqtt_topic": "rep/quiet"}],
            "mqtt2ros": [{"mqtt_topic": "rep/in", "ros_topic": "/rep/in"}]}})
        bridge = spawn(bridge_argv(params, name="rep_bridge", counters=0.2), name="rep_bridge")
        harness.wait_until(lambda: int(str(last_counters(bridge).get("connects", 0))) >= 1, 60,
                           message="the bridge to connect")
        announcement = codec.encode_msg_type(codec.RosMsgType.of(Int32, stamped=False))
        busy = codec.encode_msg_type(codec.RosMsgType.of(String, stamped=False))
        data = bytes.fromhex("2a000000")           # Int32 42, 2.x
        peer = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv311)
        peer.connect(broker.host, broker.port)
        peer.loop_start()
        sent_in = 0
        try:
            for i in range(2500):                      # 5 s at 500 msg/s on each topic, as mqtt_client writes
                peer.publish("mqtt_client/ros_msg_type/rep/busy", busy, 0, True)
                peer.publish("rep/busy", bytes.fromhex("02000000") + b"hi", 0, False)
                if i % 5 == 0:                         # and 100 msg/s on the topic the bridge reads
                    peer.publish("mqtt_client/ros_msg_type/rep/in", announcement, 0, True)
                    peer.publish("rep/in", data, 0, False)
                    sent_in += 1
                time.sleep(0.002)
        finally:
            peer.loop_stop()
            peer.disconnect()
        counters = bridge.wait_for(lambda e: e.get("event") == "counters"
                                   and (e.get("delivered") or {}).get("/rep/in", 0) >= sent_in - 5, 30)
    received = int(counters["received"])
    print(f"\npeer wrote {2 * 2500 + 2 * sent_in} messages ({2500 + sent_in} announcements); the bridge received "
          f"{received} (delivered {counters['delivered']}, scans {counters.get('scans')})")
    # the data of rep/in, plus a few announcements per scan and the first ones: far from the 3,000 announcements
    assert received < sent_in + 200, counters
    assert counters["bad_input"] == {} and bridge.alive()
