"""Issue 37 (MQTT): the bytes of the real mqtt_client 1.1.0 (f9b53da) and 2.3.0 (0649f99), captured from the
running programs (tests/fixtures/mqtt_client/, each file names its commit), read and written byte for byte;
the generation written per topic follows the peers' announcements; a type announcement is marked sent only
when the connection took it; ``~is_connected`` offers the installed interface type."""

from __future__ import annotations

import io
import json
import types
from pathlib import Path
from typing import Any, Dict, List, Optional, Set, Tuple, cast

import genpy
import pytest
import roslib.message
from std_msgs.msg import Int32, String

from micros_rt.bridges.mqtt import bridge as bridge_module
from micros_rt.qos import AdvertiseQoSOptions
from micros_rt.transports.base import EndpointSpec
from micros_rt.transports.mqtt import codec
from micros_rt.transports.mqtt.backend import MqttRule, MqttTopicWriter, parse_mqtt_section
from micros_rt.transports.mqtt.generations import PeerGenerations
from micros_rt.bridges.mqtt.params import Ros2MqttParams, parse_params

V1, V2 = codec.WireGeneration.V1, codec.WireGeneration.V2
FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "mqtt_client"
REAL = {V1: json.loads((FIXTURES / "mqtt_client-1.1.0-f9b53da.json").read_text()),
        V2: json.loads((FIXTURES / "mqtt_client-2.3.0-0649f99.json").read_text())}
CLASSES = {"std_msgs/String": String, "std_msgs/Int32": Int32}


def serialized(msg: genpy.Message) -> bytes:
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


def cases() -> List[Tuple[codec.WireGeneration, Dict[str, Any]]]:
    return [(wire, m) for wire in (V1, V2) for m in REAL[wire]["messages"]]


def case_id(case: Tuple[codec.WireGeneration, Dict[str, Any]]) -> str:
    return f"{REAL[case[0]]['version']}-{case[1]['mqtt_topic'].split('/')[-1]}"


def test_fixtures_name_the_real_programs_and_their_commits() -> None:
    assert (REAL[V1]["version"], REAL[V1]["commit"]) == ("1.1.0", "f9b53dad6af7ed15b1a1303bacb6c10055358d86")
    assert (REAL[V2]["version"], REAL[V2]["commit"]) == ("2.3.0", "0649f996dbef74133945762d9707b832d37bdfa5")


# ------------------------------------------------------------------ the real bytes, both ways


@pytest.mark.parametrize("case", cases(), ids=case_id)
def test_real_announcement_reads_as_its_generation_and_is_written_byte_for_byte(
        case: Tuple[codec.WireGeneration, Dict[str, Any]]) -> None:
    wire, m = case
    raw = bytes.fromhex(m["announcement_hex"])
    t = codec.decode_msg_type(raw)
    cls = CLASSES[m["ros_type"]]
    assert (t.wire, t.name, t.md5) == (wire, m["ros_type"], cls._md5sum)
    assert t.stamped == (None if wire is V1 else m["inject_timestamp"])
    assert codec.encode_msg_type(codec.RosMsgType.of(cls).for_wire(wire, stamped=m["inject_timestamp"])) == raw


@pytest.mark.parametrize("case", cases(), ids=case_id)
def test_real_payload_reads_and_is_written_byte_for_byte(case: Tuple[codec.WireGeneration, Dict[str, Any]]) -> None:
    wire, m = case
    raw = bytes.fromhex(m["payload_hex"])
    cls = CLASSES[m["ros_type"]]
    stamp, body = codec.decode_ros_payload(raw, stamped=codec.decode_msg_type(bytes.fromhex(m["announcement_hex"]))
                                           .stamped)
    assert cls().deserialize(bytes(body)).data == m["ros_fields"]["data"]
    if m["inject_timestamp"]:
        assert stamp is not None and abs(stamp.to_sec() - m["sent_at"]) < 5.0   # the real client's wall clock
    else:
        assert stamp is None
    assert codec.encode_ros_payload(serialized(cls(**m["ros_fields"])), wire=wire, stamp=stamp) == raw


def test_the_2x_payload_that_aborts_the_real_110_is_refused_in_words_by_a_1x_reader() -> None:
    """2.3.0's 140-byte string starts 8c: 1.1.0 takes 8c for 'stamped' and aborts; micros_rt's 1.x reading
    names the problem and goes on (that is why the bridge writes 1.x to a 1.x peer)."""
    m = next(m for m in REAL[V2]["messages"] if m["mqtt_topic"] == "capture/long_string")
    raw = bytes.fromhex(m["payload_hex"])
    assert raw[:4] == bytes.fromhex("8c000000")
    with pytest.raises(codec.CodecError, match="first byte is 140"):
        codec.decode_ros_payload(raw)


# ------------------------------------------------------------------ the peers' generation


def announce(wire: codec.WireGeneration) -> bytes:
    return bytes.fromhex(REAL[wire]["messages"][0]["announcement_hex"])


def test_no_peer_writes_the_default_and_a_setting_overrides() -> None:
    g = PeerGenerations(written=["out"])
    assert g.decide("out")[0] is V2
    fixed = PeerGenerations(fixed=V2, written=["out"])
    fixed.observe("mqtt_client/ros_msg_type/robot/odom", announce(V1))
    assert fixed.decide("out") == (V2, "set (mqtt_client_version: 2)")
    per_topic = PeerGenerations(fixed_topics={"out": V2}, written=["out"])
    per_topic.observe("mqtt_client/ros_msg_type/robot/odom", announce(V1))
    assert per_topic.decide("out")[0] is V2 and per_topic.decide("other")[0] is V1


@pytest.mark.parametrize("wire", [V1, V2])
def test_the_real_peers_announcement_decides(wire: codec.WireGeneration) -> None:
    g = PeerGenerations(written=["cmd"])
    assert g.observe("mqtt_client/ros_msg_type/robot/odom", announce(wire))
    assert g.decide("cmd")[0] is wire
    assert g.observe("mqtt_client/ros_msg_type/robot/odom", announce(wire)) is False   # a repeat changes nothing


def test_own_topics_and_echoes_and_bad_announcements_are_not_peers() -> None:
    g = PeerGenerations(written=["cmd"])
    assert not g.observe("mqtt_client/ros_msg_type/cmd", announce(V1))     # a retained one of an earlier run
    g.published("late", announce(V1))
    assert not g.observe("mqtt_client/ros_msg_type/late", announce(V1))    # this client's own echo
    assert not g.observe("mqtt_client/ros_msg_type/x", b"\x01")             # does not decode: says nothing
    assert g.peers() == {} and g.decide("cmd")[0] is V2
    g.observe("mqtt_client/ros_msg_type/robot/odom", announce(V1))
    assert g.observe("mqtt_client/ros_msg_type/robot/odom", b"")           # retained announcement cleared
    assert g.decide("cmd")[0] is V2


def test_mixed_generations_nearest_topic_then_1x() -> None:
    g = PeerGenerations(written=["robot1/cmd", "robot2/cmd", "fleet"])
    g.observe("mqtt_client/ros_msg_type/robot1/odom", announce(V1))
    g.observe("mqtt_client/ros_msg_type/robot2/odom", announce(V2))
    assert g.decide("robot1/cmd")[0] is V1
    assert g.decide("robot2/cmd")[0] is V2
    wire, why = g.decide("fleet")
    assert wire is V1 and "both generations" in why and "set mqtt_client_version on this topic" in why


def test_per_topic_setting_is_parsed() -> None:
    params, _ = parse_params({"bridge": {"ros2mqtt": [
        {"ros_topic": "/a", "mqtt_topic": "a", "mqtt_client_version": 1}, {"ros_topic": "/b", "mqtt_topic": "b"}]}})
    assert [e.wire for e in params.ros2mqtt] == [V1, None] and params.wire_set is False
    params, _ = parse_params({"bridge": {"mqtt_client_version": "2.x", "ros2mqtt": [{"ros_topic": "/b",
                                                                                    "mqtt_topic": "b"}]}})
    assert params.wire_set is True and params.wire is V2


# ------------------------------------------------------------------ announcements marked sent only when sent


class FlakyConnection:
    """Not live at first (sending not enabled yet: publish drops, as MqttConnection does), then live."""

    def __init__(self) -> None:
        self.live = False
        self.published: List[Tuple[str, bytes, bool]] = []
        self.subscribed: Dict[str, Any] = {}

    @property
    def can_send(self) -> bool:
        return self.live

    is_live = can_send

    def publish(self, topic: str, payload: bytes, *, qos: int = 0, retain: bool = False,
                properties: Any = None) -> bool:
        if not self.live:
            return False
        self.published.append((topic, payload, retain))
        return True

    def subscribe(self, topic: str, qos: int, callback: Any) -> None:
        self.subscribed[topic] = callback


def test_backend_writer_announces_after_a_dropped_first_try() -> None:
    settings = parse_mqtt_section({"topics": {"/t": {}}}, source="p")
    conn = FlakyConnection()
    backend = types.SimpleNamespace(settings=settings, connection=conn, graph="here", generation=1,
                                    source="here|node")
    writer = MqttTopicWriter(cast(Any, backend), MqttRule(key="/t", order=0),
                             EndpointSpec(topic="/t", data_class=String, queue_size=1, latch=False, tag={}),
                             AdvertiseQoSOptions())
    writer.send(writer.prepare(String(data="early")))       # within ~0.1 s of connecting: nothing goes out
    conn.live = True
    writer.send(writer.prepare(String(data="later")))
    assert [t for t, _, _ in conn.published] == ["mqtt_client/ros_msg_type/t", "t"]
    assert conn.published[0][2] is True                    # retained


def fake_bridge(conn: FlakyConnection, generations: PeerGenerations) -> Any:
    return types.SimpleNamespace(connection=conn, generations=generations, problems=bridge_module._Problems(),
                                 params=types.SimpleNamespace(wire=V2), end_watch=lambda: None)


def test_bridge_topic_announces_after_a_dropped_first_try_and_on_a_new_generation() -> None:
    conn = FlakyConnection()
    generations = PeerGenerations(written=["out"])
    topic = bridge_module._Ros2Mqtt(fake_bridge(conn, generations), Ros2MqttParams(ros_topic="/out",
                                                                                   mqtt_topic="out"))
    topic.on_ros(String(data="early"))                      # not live: dropped, neither marked nor held
    conn.live = True
    topic.on_ros(String(data="a"))
    topic.on_ros(String(data="b"))                          # announced once; held: no peer's generation known
    assert conn.published == [("mqtt_client/ros_msg_type/out", codec.encode_msg_type(
        codec.RosMsgType.of(String, stamped=False)), True)]
    assert topic.holding and topic.held == 2
    # a 1.1.0 peer shows up: re-announced at once in 1.x, the held messages and the next in 1.x, in order
    generations.observe("mqtt_client/ros_msg_type/peer/odom", announce(V1))
    topic.redecide()
    topic.on_ros(String(data="c"))
    assert conn.published[1:] == [
        ("mqtt_client/ros_msg_type/out", codec.encode_msg_type(codec.RosMsgType.of(String)), True),
        ("out", b"\x00" + serialized(String(data="a")), False), ("out", b"\x00" + serialized(String(data="b")), False),
        ("out", b"\x00" + serialized(String(data="c")), False)]
    assert not topic.holding


def test_bridge_topic_writes_the_default_when_no_peer_announces_within_the_hold() -> None:
    conn = FlakyConnection()
    conn.live = True
    topic = bridge_module._Ros2Mqtt(fake_bridge(conn, PeerGenerations(written=["out"])),
                                    Ros2MqttParams(ros_topic="/out", mqtt_topic="out"))
    topic.on_ros(String(data="a"))
    topic.check_hold(100.0, 100.0 - bridge_module.PEER_HOLD / 2)     # within the hold: still held
    assert [t for t, _, _ in conn.published] == ["mqtt_client/ros_msg_type/out"]
    topic.check_hold(100.0, 100.0 - bridge_module.PEER_HOLD)         # expired: 2.x, the default
    topic.on_ros(String(data="b"))
    assert conn.published[1:] == [("out", serialized(String(data="a")), False),
                                  ("out", serialized(String(data="b")), False)]


def test_bridge_topic_with_a_setting_never_holds() -> None:
    conn = FlakyConnection()
    conn.live = True
    topic = bridge_module._Ros2Mqtt(fake_bridge(conn, PeerGenerations(fixed=V2, written=["out"])),
                                    Ros2MqttParams(ros_topic="/out", mqtt_topic="out"))
    topic.on_ros(String(data="a"))
    assert not topic.holding and conn.published[1:] == [("out", serialized(String(data="a")), False)]


# ------------------------------------------------------------------ ~is_connected's type


class FakeSrv:
    def __init__(self, md5: str) -> None:
        self._md5sum = md5


@pytest.mark.parametrize("installed, preferred, expect", [
    ({"mqtt_client/IsConnected"}, V2, "mqtt_client"),                 # a 1.x install, default setting
    ({"mqtt_client_interfaces/IsConnected"}, V1, "mqtt_client_interfaces"),
    ({"mqtt_client/IsConnected", "mqtt_client_interfaces/IsConnected"}, V1, "mqtt_client"),
    (set(), V2, None),
])
def test_is_connected_offers_the_installed_type(monkeypatch: pytest.MonkeyPatch, installed: Set[str],
                                                preferred: codec.WireGeneration, expect: Optional[str]) -> None:
    def lookup(name: str, reload_on_error: bool = False) -> Any:
        return FakeSrv(bridge_module.IS_CONNECTED_MD5) if name in installed else None

    monkeypatch.setattr(roslib.message, "get_service_class", lookup)
    assert bridge_module.installed_is_connected_package(preferred) == expect
    if expect is not None:
        cls = bridge_module.is_connected_service_class(preferred, package=expect)
        assert cls._type == f"{expect}/IsConnected" and cls._md5sum == bridge_module.IS_CONNECTED_MD5
