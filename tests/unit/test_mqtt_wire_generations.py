"""mqtt_client's two ROS 1 wire generations, byte for byte: 1.x (1.0-1.1: a flag byte before each payload,
``RosMsgType`` of three strings) and 2.x (2.0-2.3: no flag byte, ``RosMsgType`` with a fourth field
``bool stamped``). Fixtures are the bytes the real mqtt_client 2.3.0 put on the wire (issue 22,
``mosquitto_sub -F '%t %x'``) and the layouts in mqtt_client's sources (MqttClient.cpp, RosMsgType.msg at
tags v1.1.0 and v2.3.0 of ika-rwth-aachen/mqtt_client). Both directions: what micros_rt writes in each
generation, and what it reads from each, also through the back end's topic reader and writer."""

from __future__ import annotations

import io
import types
from typing import Any, Dict, List, Tuple, cast

import genpy
import pytest
from std_msgs.msg import Int32, String

from micros_rt.transports.mqtt import codec
from micros_rt.transports.mqtt.backend import MqttRule, MqttTopicReader, MqttTopicWriter, parse_mqtt_section
from micros_rt.bridges.mqtt.bridge import is_connected_service_class
from micros_rt.bridges.mqtt.params import ParamsError, parse_params
from micros_rt.qos import AdvertiseQoSOptions
from micros_rt.transports.base import EndpointSpec

V1, V2 = codec.WireGeneration.V1, codec.WireGeneration.V2

STRING_MD5 = "992ce8a1687cec8c8bd883ec73ca41d1"
#: mqtt_client 2.3.0's announcement of std_msgs/String with inject_timestamp (from the wire, issue 22):
#: md5, name, definition ("string data\n"), then 01 = stamped.
REAL_230_STRING_TYPE = bytes.fromhex(
    "20000000" + STRING_MD5.encode().hex()
    + "0f000000" + b"std_msgs/String".hex()
    + "0c000000" + b"string data\n".hex()
    + "01")
#: the same announcement from mqtt_client 1.x (and micros_rt before issue 22): without the final byte.
V1_STRING_TYPE = REAL_230_STRING_TYPE[:-1]
#: mqtt_client 2.3.0's payload of String(data='hi') with inject_timestamp: stamp secs, nsecs, message.
REAL_230_STAMPED_HI = bytes.fromhex("eb1b056b" "34440a18" "02000000" "6869")
STAMP_230 = genpy.Time(0x6B051BEB, 0x180A4434)


def serialized(msg: genpy.Message) -> bytes:
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


# ------------------------------------------------------------------ type announcements


def test_real_230_announcement_reads_as_2x_stamped_and_is_written_byte_for_byte() -> None:
    t = codec.decode_msg_type(REAL_230_STRING_TYPE)
    assert (t.md5, t.name, t.definition, t.stamped, t.wire) == (STRING_MD5, "std_msgs/String", "string data\n",
                                                                True, V2)
    assert codec.encode_msg_type(codec.RosMsgType.of(String, stamped=True)) == REAL_230_STRING_TYPE


def test_2x_unstamped_announcement_ends_in_zero() -> None:
    raw = codec.encode_msg_type(codec.RosMsgType.of(String, stamped=False))
    assert raw == V1_STRING_TYPE + b"\x00"
    assert codec.decode_msg_type(raw).stamped is False


def test_1x_announcement_is_three_strings_and_reads_as_1x() -> None:
    assert codec.encode_msg_type(codec.RosMsgType.of(String)) == V1_STRING_TYPE
    t = codec.decode_msg_type(V1_STRING_TYPE)
    assert t.stamped is None and t.wire is V1 and t == codec.RosMsgType.of(String)


def test_for_wire_keeps_stamped_only_in_2x() -> None:
    t = codec.RosMsgType.of(String)
    assert t.for_wire(V1, stamped=True).stamped is None
    assert t.for_wire(V2, stamped=True).stamped is True and t.for_wire(V2, stamped=False).stamped is False


@pytest.mark.parametrize("raw, words", [
    (V1_STRING_TYPE + b"\x02", "stamped field .* is 2, must be 0 or 1"),
    (V1_STRING_TYPE + b"\x01\x00", "2 bytes after its definition"),
])
def test_announcement_with_a_bad_tail_is_an_error_in_words(raw: bytes, words: str) -> None:
    with pytest.raises(codec.CodecError, match=words):
        codec.decode_msg_type(raw)


# ------------------------------------------------------------------ payloads


def test_real_230_stamped_payload_reads_with_stamped_true() -> None:
    stamp, body = codec.decode_ros_payload(REAL_230_STAMPED_HI, stamped=True)
    assert stamp == STAMP_230 and String().deserialize(bytes(body)).data == "hi"
    # what micros_rt did before issue 22 (a 1.x reader): the first stamp byte taken for a flag
    with pytest.raises(codec.CodecError, match="first byte is 235"):
        codec.decode_ros_payload(REAL_230_STAMPED_HI)


def test_2x_payloads_are_written_without_flag_byte() -> None:
    hi = serialized(String(data="hi"))
    assert codec.encode_ros_payload(hi, wire=V2, stamp=STAMP_230) == REAL_230_STAMPED_HI
    assert codec.encode_ros_payload(hi, wire=V2) == bytes.fromhex("02000000" "6869")


def test_1x_payloads_keep_their_flag_byte() -> None:
    hi = serialized(String(data="hi"))
    assert codec.encode_ros_payload(hi, wire=V1, stamp=STAMP_230) == b"\x01" + REAL_230_STAMPED_HI
    assert codec.encode_ros_payload(hi, wire=V1) == bytes.fromhex("00" "02000000" "6869")
    stamp, body = codec.decode_ros_payload(b"\x01" + REAL_230_STAMPED_HI)
    assert stamp == STAMP_230 and bytes(body) == hi


def test_2x_unstamped_payload_starting_with_a_flag_like_byte_is_all_message() -> None:
    """Int32(1) is 01 00 00 00: a reader that guessed the form from the first byte would take a stamp."""
    payload = codec.encode_ros_payload(serialized(Int32(data=1)), wire=V2)
    assert payload == bytes.fromhex("01000000")
    stamp, body = codec.decode_ros_payload(payload, stamped=False)
    assert stamp is None and Int32().deserialize(bytes(body)).data == 1


def test_2x_stamped_payload_shorter_than_its_stamp() -> None:
    with pytest.raises(codec.CodecError, match="2.x payload of 5 bytes is shorter than its 8-byte timestamp"):
        codec.decode_ros_payload(b"\x00" * 5, stamped=True)


# ------------------------------------------------------------------ parameters and the service


@pytest.mark.parametrize("value, wire", [(None, V2), (2, V2), (1, V1), ("1.x", V1), ("2.x", V2)])
def test_bridge_mqtt_client_version(value: Any, wire: codec.WireGeneration) -> None:
    bridge: Dict[str, Any] = {"mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a"}]}
    if value is not None:
        bridge["mqtt_client_version"] = value
    params, warnings = parse_params({"bridge": bridge})
    assert params.wire is wire
    assert not any("mqtt_client_version" in w for w in warnings)   # mqtt_client has no such key to log


@pytest.mark.parametrize("value", [3, True, "2.4", "ros2"])
def test_bad_mqtt_client_version_names_the_choices(value: Any) -> None:
    with pytest.raises(ParamsError, match=r"'bridge/mqtt_client_version' is .*2 \(mqtt_client 2.0-2.3"):
        parse_params({"bridge": {"mqtt_client_version": value, "mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a"}]}})


@pytest.mark.parametrize("key", ["version", "verify", "alpn_protos"])
def test_2x_tls_keys_are_refused_in_words(key: str) -> None:
    tls = {"certificate": "c.pem", "key": "k.pem", key: 1}
    with pytest.raises(ParamsError, match=rf"'client/tls/{key}' \(mqtt_client 2.x\) is not supported"):
        parse_params({"client": {"tls": tls}, "bridge": {"mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a"}]}})


def test_profile_section_takes_mqtt_client_version() -> None:
    assert parse_mqtt_section({"topics": {}}, source="p").wire is V2
    assert parse_mqtt_section({"topics": {}, "mqtt_client_version": 1}, source="p").wire is V1


def test_is_connected_type_per_generation_same_md5() -> None:
    v1, v2 = is_connected_service_class(V1), is_connected_service_class(V2)
    assert (v1._type, v2._type) == ("mqtt_client/IsConnected", "mqtt_client_interfaces/IsConnected")
    # md5 of a service: its request text ('') and response text ('bool connected'), not its package
    assert v1._md5sum == v2._md5sum == "e0cdaf65159c7f3563426650fb8d3f64"


# ------------------------------------------------------------------ the back end's reader and writer


class FakeConnection:
    def __init__(self) -> None:
        self.subscribed: Dict[str, Any] = {}
        self.published: List[Tuple[str, bytes, bool]] = []
        self.can_send = self.is_live = True

    def subscribe(self, topic: str, qos: int, callback: Any) -> None:
        self.subscribed[topic] = callback

    def publish(self, topic: str, payload: bytes, *, qos: int, retain: bool, properties: Any = None) -> bool:
        self.published.append((topic, payload, retain))
        return True


def fake_backend(wire: codec.WireGeneration) -> Any:
    settings = parse_mqtt_section({"topics": {"/t": {}}, "mqtt_client_version": int(wire)}, source="p")
    return types.SimpleNamespace(settings=settings, connection=FakeConnection(), graph="here", generation=1,
                                 source="here|node")


def spec(cls: type) -> EndpointSpec:
    return EndpointSpec(topic="/t", data_class=cls, queue_size=10, latch=False, tag={})


def reader(cls: type) -> Tuple[Any, List[genpy.Message]]:
    got: List[genpy.Message] = []
    backend = fake_backend(V2)
    rule = MqttRule(key="/t", order=0)
    MqttTopicReader(backend, rule, spec(cls), None, got.append)
    return backend.connection.subscribed, got


@pytest.mark.parametrize("announcement, payloads", [
    (REAL_230_STRING_TYPE, [REAL_230_STAMPED_HI]),
    (V1_STRING_TYPE, [b"\x01" + REAL_230_STAMPED_HI, bytes.fromhex("00" "02000000" "6869")]),
    (V1_STRING_TYPE + b"\x00", [bytes.fromhex("02000000" "6869")]),
])
def test_reader_holds_payloads_until_the_announcement_then_reads_its_form(announcement: bytes,
                                                                          payloads: List[bytes]) -> None:
    subscribed, got = reader(String)
    for p in payloads:
        subscribed["t"]("t", p, None)
    assert got == []                                     # form unknown: held, not misread
    subscribed["mqtt_client/ros_msg_type/t"]("mqtt_client/ros_msg_type/t", announcement, None)
    assert [m.data for m in got] == ["hi"] * len(payloads)
    subscribed["t"]("t", payloads[0], None)              # and after it, directly
    assert len(got) == len(payloads) + 1


def test_reader_follows_a_peer_that_changes_generation() -> None:
    subscribed, got = reader(Int32)
    announce = subscribed["mqtt_client/ros_msg_type/t"]
    announce("", codec.encode_msg_type(codec.RosMsgType.of(Int32, stamped=False)), None)
    subscribed["t"]("t", bytes.fromhex("01000000"), None)            # 2.x: Int32(1), no flag byte
    announce("", codec.encode_msg_type(codec.RosMsgType.of(Int32)), None)
    subscribed["t"]("t", bytes.fromhex("00" "02000000"), None)       # 1.x: flag 0, Int32(2)
    assert [m.data for m in got] == [1, 2]


@pytest.mark.parametrize("wire, type_tail, payload", [
    (V2, b"\x00", bytes.fromhex("02000000" "6869")),
    (V1, b"", bytes.fromhex("00" "02000000" "6869")),
])
def test_writer_writes_its_generation(wire: codec.WireGeneration, type_tail: bytes, payload: bytes) -> None:
    backend = fake_backend(wire)
    writer = MqttTopicWriter(backend, MqttRule(key="/t", order=0), spec(String), AdvertiseQoSOptions())
    writer.send(writer.prepare(String(data="hi")))
    assert backend.connection.published == [
        ("mqtt_client/ros_msg_type/t", V1_STRING_TYPE + type_tail, True), ("t", payload, False)]


# ------------------------------------------------------------------ the bridge's MQTT -> ROS side


class FakePublisher:
    def __init__(self, topic: str, cls: type) -> None:
        self.topic, self.cls = topic, cls
        self.sent: List[Any] = []

    def publish(self, msg: Any) -> None:
        self.sent.append(msg)

    def unregister(self) -> None:
        pass


class FakeNodeHandle:
    def __init__(self) -> None:
        self.publishers: Dict[str, FakePublisher] = {}

    def advertise(self, topic: str, cls: type, queue_size: int, latch: bool = False) -> FakePublisher:
        self.publishers[topic] = FakePublisher(topic, cls)
        return self.publishers[topic]


def bridge_topic(monkeypatch: pytest.MonkeyPatch, **entry: Any) -> Tuple[Any, FakeNodeHandle]:
    from micros_rt.bridges.mqtt import bridge as bridge_module
    from micros_rt.bridges.mqtt.params import Mqtt2RosParams

    monkeypatch.setattr(bridge_module, "_await_subscribers", lambda pub: None)   # no ROS master here
    nh = FakeNodeHandle()
    fake_bridge = types.SimpleNamespace(nh=nh, problems=bridge_module._Problems(),
                                        note_read_generation=lambda topic, wire: None, request_scan=lambda: None,
                                        connection=types.SimpleNamespace(unsubscribe=lambda topic: None))
    topic = bridge_module._Mqtt2Ros(cast(Any, fake_bridge), Mqtt2RosParams(mqtt_topic="t", ros_topic="/t", **entry))
    return topic, nh


def test_bridge_holds_real_230_payload_then_reads_it_stamped_with_latency(monkeypatch: pytest.MonkeyPatch) -> None:
    topic, nh = bridge_topic(monkeypatch)
    topic.on_data("t", REAL_230_STAMPED_HI)
    assert nh.publishers == {}                                       # no type yet: held
    topic.on_type("mqtt_client/ros_msg_type/t", REAL_230_STRING_TYPE)
    assert [m.data for m in nh.publishers["/t"].sent] == ["hi"]
    latency = nh.publishers["~latencies/t"].sent
    assert len(latency) == 1 and latency[0].data > 0                 # now minus the stamp (2026-11-24 05:08:59 UTC)
    assert topic.bridge.problems.counts == {}


def test_bridge_with_ros_type_still_waits_for_the_announcement(monkeypatch: pytest.MonkeyPatch) -> None:
    """ros_type fixes the class, not the form: a 2.x Int32(1) (01 00 00 00) read as 1.x would be a stamp."""
    topic, nh = bridge_topic(monkeypatch, ros_type="std_msgs/Int32")
    topic.on_data("t", bytes.fromhex("01000000"))
    assert nh.publishers["/t"].sent == []
    topic.on_type("", codec.encode_msg_type(codec.RosMsgType.of(Int32, stamped=False)))
    topic.on_data("t", bytes.fromhex("02000000"))
    topic.on_type("", codec.encode_msg_type(codec.RosMsgType.of(Int32)))            # the peer is now 1.x
    topic.on_data("t", bytes.fromhex("00" "03000000"))
    assert [m.data for m in nh.publishers["/t"].sent] == [1, 2, 3]
    assert "~latencies/t" not in nh.publishers and topic.bridge.problems.counts == {}
