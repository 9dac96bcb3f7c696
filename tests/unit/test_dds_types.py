"""The generated CDR codec: byte-identical to cyclonedds' own serializer, ROS 2 names and layout."""

from __future__ import annotations

import struct
from typing import Any

import genpy
import pytest
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, Twist
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2, PointField
from std_msgs.msg import Bool, Byte, Char, Duration, Float64MultiArray, Header, Int8, Int32, String, Time, UInt64

from micros_rt.transports.dds.types import MalformedSampleError, dds_type_for
from micros_rt.exceptions import TypeMappingError

HEADER = Header(seq=7, stamp=genpy.Time(1700000000, 123456789), frame_id="map")

MESSAGES: list[Any] = [
    String(data="hello"),
    String(data=""),
    String(data="héllo wörld ✓"),
    Int32(data=-5),
    Int8(data=-128),
    Byte(data=-1),
    Char(data=255),
    Bool(data=True),
    UInt64(data=2**64 - 1),
    Time(data=genpy.Time(5, 6)),
    Duration(data=genpy.Duration(-3, 500)),
    HEADER,
    Twist(),
    PoseStamped(header=HEADER, pose=Pose()),
    PoseArray(header=HEADER, poses=[Pose(), Pose()]),
    Image(header=HEADER, height=2, width=3, encoding="rgb8", step=9, data=bytes(range(18))),
    CameraInfo(header=HEADER, height=480, width=640, distortion_model="plumb_bob", D=[0.1, -0.2, 0.0, 0.0, 0.01],
               K=[1.0] * 9, R=[0.0] * 9, P=[2.0] * 12),
    LaserScan(header=HEADER, angle_min=-1.0, angle_max=1.0, ranges=[1.0, 2.5, 3.0], intensities=[]),
    PointCloud2(header=HEADER, height=1, width=2, fields=[PointField(name="x", offset=0, datatype=7, count=1)],
                point_step=4, row_step=8, data=b"\x01" * 8, is_dense=True),
    Float64MultiArray(data=[1.5, -2.25]),
]


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: f"{m._type}")
def test_encode_is_byte_identical_to_cyclonedds(msg: Any) -> None:
    t = dds_type_for(type(msg))
    data = t.encode(msg)
    assert data[:4] == b"\x00\x01\x00\x00"  # plain CDR, little endian, as ROS 2 writes
    assert t.idl_class.deserialize(data).serialize() == data


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: f"{m._type}")
def test_decode_round_trip(msg: Any) -> None:
    t = dds_type_for(type(msg))
    back = t.decode(t.encode(msg))
    if getattr(msg, "_has_header", False) or msg._type == "std_msgs/Header":
        head = msg.header if msg._has_header else msg
        expect_seq, head.seq = head.seq, 0  # ROS 2 has no seq: the subscriber numbers messages itself
        try:
            assert back == msg
        finally:
            head.seq = expect_seq
    else:
        assert back == msg


def test_decodes_what_cyclonedds_serializes() -> None:
    t = dds_type_for(CameraInfo)
    sample = t.idl_class.deserialize(t.encode(MESSAGES[16]))
    assert t.decode(sample.serialize()).D == (0.1, -0.2, 0.0, 0.0, 0.01)


def test_ros2_type_names_and_fields() -> None:
    assert dds_type_for(String).type_name == "std_msgs::msg::dds_::String_"
    fields = list(dds_type_for(CameraInfo).idl_class.__annotations__)
    assert "d" in fields and "k" in fields and "D" not in fields  # ROS 2 renamed D K R P
    assert list(dds_type_for(Header).idl_class.__annotations__) == ["stamp", "frame_id"]  # no seq


def test_header_layout_is_ros2() -> None:
    data = dds_type_for(Header).encode(HEADER)
    sec, nanosec, n = struct.unpack_from("<iII", data, 4)
    assert (sec, nanosec) == (1700000000, 123456789)
    assert data[16:16 + n] == b"map\x00"


def test_uint8_array_moves_as_bytes() -> None:
    t = dds_type_for(Image)
    img = Image(height=480, width=640, encoding="rgb8", step=1920, data=bytes(range(256)) * 3600)
    back = t.decode(t.encode(img))
    assert isinstance(back.data, bytes) and back.data == img.data
    img.data = list(img.data[:10])  # genpy also accepts a list of ints
    assert t.decode(t.encode(img)).data == bytes(range(10))


def test_big_endian_samples_decode() -> None:
    t = dds_type_for(Int32)
    assert t.decode(b"\x00\x00\x00\x00" + struct.pack(">i", -7)).data == -7


def test_bad_input_is_a_clear_error() -> None:
    t = dds_type_for(CameraInfo)
    with pytest.raises(genpy.SerializationError, match="field K: fixed-size array needs 9 elements, got 8"):
        t.encode(CameraInfo(K=[1.0] * 8))
    with pytest.raises(MalformedSampleError, match="unsupported CDR encapsulation"):
        t.decode(b"\x00\x07\x00\x00" + bytes(8))
    with pytest.raises(genpy.SerializationError, match="field data: 'x' is not an integer"):
        dds_type_for(Int32).encode(Int32(data="x"))
    with pytest.raises(TypeMappingError, match="not a genpy"):
        dds_type_for(int)


def test_a_bad_field_is_named_after_a_run_time_header_class_was_registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """A run-time type that nests std_msgs/Header registers a run-time Header class (genpy.dynamic) in the process;
    an installed message's own Header is then another class of the same type. The error still names the field
    (it said ``field header: ... is not a std_msgs/Header`` when ``tests/unit`` had run before the contract)."""
    import genpy.dynamic

    from micros_rt.transports.dds import types

    monkeypatch.setattr(types, "_runtime_classes", {})
    classes = genpy.dynamic.generate_dynamic("std_msgs/Header", Header._full_text)
    types.register_message_classes(classes)
    assert types._msg_class("std_msgs/Header") is not Header  # the situation: two classes of one type
    bad = PoseStamped()
    bad.header.frame_id = 123
    assert types.describe_bad_field(bad, "geometry_msgs/PoseStamped") == \
        "field header.frame_id: 123 is not a string"
    other = types.describe_bad_field(String(data="x"), "geometry_msgs/PoseStamped")
    assert other is not None and other.startswith("field (message)"), other  # another type is still refused
