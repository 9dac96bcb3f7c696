"""mqtt_client's wire format, byte for byte, and the primitive text and JSON codecs."""

from __future__ import annotations

import io
import math

import genpy
import pytest
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Image
from std_msgs.msg import Bool, Char, Float32, Float64, Int8, Int32, Int64, String, UInt8, UInt64

from micros_rt.transports.mqtt import codec

V1, V2 = codec.WireGeneration.V1, codec.WireGeneration.V2


def serialized(msg: genpy.Message) -> bytes:
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


# ------------------------------------------------------------------ framing fixtures


def test_unstamped_string_payload_is_zero_then_ros1_serialization() -> None:
    payload = codec.encode_ros_payload(serialized(String(data="Hello MQTT!")), wire=V1)
    assert payload == bytes.fromhex("00" "0b000000") + b"Hello MQTT!"


def test_stamped_payload_is_one_then_time_then_message() -> None:
    stamp = genpy.Time(1_700_000_000, 123_456_789)
    payload = codec.encode_ros_payload(serialized(Int32(data=42)), wire=V1, stamp=stamp)
    # [1 | secs uint32 LE | nsecs uint32 LE | int32 LE]
    assert payload == bytes.fromhex("01" "00f15365" "15cd5b07" "2a000000")
    got_stamp, body = codec.decode_ros_payload(payload)
    assert got_stamp == stamp and bytes(body) == bytes.fromhex("2a000000")


def test_unstamped_decode_returns_the_message_bytes() -> None:
    stamp, body = codec.decode_ros_payload(bytes.fromhex("00" "2a000000"))
    assert stamp is None and Int32().deserialize(bytes(body)).data == 42


def test_pose_stamped_round_trip_through_the_framing() -> None:
    msg = PoseStamped()
    msg.header.seq, msg.header.stamp, msg.header.frame_id = 7, genpy.Time(5, 6), "map"
    msg.pose.position.x, msg.pose.orientation.w = 1.5, 1.0
    _, body = codec.decode_ros_payload(codec.encode_ros_payload(serialized(msg), wire=V1,
                                                                stamp=genpy.Time(1, 2)))
    back = PoseStamped().deserialize(bytes(body))
    assert back == msg


@pytest.mark.parametrize("payload, words", [
    (b"", "empty payload"),
    (b"\x02abc", "first byte is 2"),
    (b"\x01\x00\x00", "shorter than its 8-byte timestamp"),
    (bytes.fromhex("01" "00000000" "00ca9a3b"), "nanoseconds"),
])
def test_bad_framing_is_an_error_in_words(payload: bytes, words: str) -> None:
    with pytest.raises(codec.CodecError, match=words):
        codec.decode_ros_payload(payload)


def test_type_announcement_is_three_ros1_strings() -> None:
    t = codec.RosMsgType.of(String)
    raw = codec.encode_msg_type(t)
    assert raw == (bytes.fromhex("20000000") + b"992ce8a1687cec8c8bd883ec73ca41d1"
                   + bytes.fromhex("0f000000") + b"std_msgs/String"
                   + len(String._full_text).to_bytes(4, "little") + String._full_text.encode())
    assert codec.decode_msg_type(raw) == t
    assert codec.ROS_MSG_TYPE_PREFIX == "mqtt_client/ros_msg_type/"


@pytest.mark.parametrize("raw", [b"", b"\x05\x00\x00\x00ab", codec.encode_msg_type(codec.RosMsgType("x", "NoSlash", ""))])
def test_bad_type_announcement(raw: bytes) -> None:
    with pytest.raises(codec.CodecError):
        codec.decode_msg_type(raw)


# ------------------------------------------------------------------ primitive text


@pytest.mark.parametrize("msg, text", [
    (String(data="hello world"), "hello world"), (Bool(data=True), "true"), (Bool(data=False), "false"),
    (Char(data=65), "65"), (UInt8(data=255), "255"), (Int8(data=-5), "-5"), (Int32(data=42), "42"),
    (Int64(data=-2**63), str(-2**63)), (UInt64(data=2**64 - 1), str(2**64 - 1)),
    (Float32(data=1.1), "1.1"), (Float64(data=0.1), "0.1"), (Float32(data=3.0), "3"),
])
def test_primitive_to_text(msg: genpy.Message, text: str) -> None:
    assert codec.msg_to_text(msg) == text


def test_non_primitive_is_sent_as_its_yaml_text() -> None:
    assert "position" in codec.msg_to_text(PoseStamped())


@pytest.mark.parametrize("text, cls, value", [
    ("true", Bool, True), ("false", Bool, False), ("69", Int32, 69), ("-3", Int32, -3),
    ("2147483648", Float32, 2147483648.0), ("3.5", Float32, 3.5), ("1e3", Float32, 1000.0),
    ("hello", String, "hello"), ("", String, ""), ("True", Bool, True), ("FALSE", Bool, False),
    ("1.5.2", String, "1.5.2"),
])
def test_probe_order_bool_int_float_string(text: str, cls: type, value: object) -> None:
    msg = codec.probe_primitive(text)
    assert type(msg) is cls and msg.data == value  # type: ignore[attr-defined]


@pytest.mark.parametrize("text, cls, words", [
    ("abc", Int32, "not an integer"), ("300", UInt8, "does not fit std_msgs/UInt8"), ("x", Float64, "not a number"),
    ("maybe", Bool, "not a bool"), ("1", PoseStamped, "not a primitive type"),
])
def test_text_that_fits_no_type(text: str, cls: type, words: str) -> None:
    with pytest.raises(codec.CodecError, match=words):
        codec.text_to_msg(text, cls)


def test_text_for_a_fixed_type() -> None:
    assert codec.text_to_msg(" 69 ", Int32).data == 69
    assert codec.text_to_msg("1", Bool).data is True


# ------------------------------------------------------------------ JSON


def test_json_has_every_field_and_round_trips() -> None:
    img = Image(height=2, width=3, encoding="mono8", step=3, data=bytes(range(6)))
    img.header.stamp = genpy.Time(10, 20)
    text = codec.msg_to_json(img)
    assert '"encoding":"mono8"' in text and '"data":[0,1,2,3,4,5]' in text and '"secs":10' in text
    assert codec.json_to_msg(text, Image) == img


def test_json_non_finite_floats_survive() -> None:
    back = codec.json_to_msg(codec.msg_to_json(Float64(data=math.inf)), Float64)
    assert back.data == math.inf


@pytest.mark.parametrize("text, words", [
    ("{", "not JSON"), ('{"nope": 1}', "has no field 'nope'"), ('{"data": "x"}', "does not fit std_msgs/Int32"),
    ("[1]", "expected a JSON object"),
])
def test_bad_json(text: str, words: str) -> None:
    with pytest.raises(codec.CodecError, match=words):
        codec.json_to_msg(text, Int32)


# ------------------------------------------------------------------ RPC (AimRT's packets)


def test_rpc_request_and_response_layout() -> None:
    req = codec.encode_rpc_request("ros1", "aimrt_rpc_rsp/c1/%2Fadd", 7, b"\x01\x02")
    assert req == b"\x04ros1" + b"\x17aimrt_rpc_rsp/c1/%2Fadd" + bytes.fromhex("07000000") + b"\x01\x02"
    assert codec.decode_rpc_request(req) == ("ros1", "aimrt_rpc_rsp/c1/%2Fadd", 7, b"\x01\x02")
    rsp = codec.encode_rpc_response("ros1", 7, 0, b"ok")
    assert rsp == b"\x04ros1" + bytes.fromhex("07000000" "00000000") + b"ok"
    assert codec.decode_rpc_response(rsp) == ("ros1", 7, 0, b"ok")


@pytest.mark.parametrize("payload", [b"", b"\x09ros1", b"\x04ros1\x03ab", b"\x04ros1\x00\x01\x02"])
def test_bad_rpc_request(payload: bytes) -> None:
    with pytest.raises(codec.CodecError):
        codec.decode_rpc_request(payload)


def test_bad_rpc_response() -> None:
    with pytest.raises(codec.CodecError, match="msg id and status"):
        codec.decode_rpc_response(b"\x04ros1\x01\x00")


def test_json_of_numpy_and_array_values_is_the_json_of_the_list() -> None:
    import array

    import numpy
    from rospy.numpy_msg import numpy_msg
    from std_msgs.msg import Float32MultiArray

    values = [0.5, -1.25, 3.0]
    expect = codec.msg_to_json(Float32MultiArray(data=values))
    assert codec.msg_to_json(numpy_msg(Float32MultiArray)(data=numpy.array(values, dtype=numpy.float32))) == expect
    assert codec.msg_to_json(Float32MultiArray(data=array.array("f", values))) == expect
