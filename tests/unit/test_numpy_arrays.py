"""Numeric arrays in the DDS codec: numpy and array.array values are encoded as blocks (and converted
value by value when their dtype is not the field's), and rospy.numpy_msg classes decode to numpy arrays
that view the received sample, as rospy's own numpy deserializer gives."""

from __future__ import annotations

import array
import struct
from typing import Any

import genpy
import numpy
import pytest
from rospy.numpy_msg import numpy_msg
from sensor_msgs.msg import ChannelFloat32, Image, Imu, LaserScan, PointCloud
from std_msgs.msg import (Float64MultiArray, Int16MultiArray, Int32MultiArray, Int64MultiArray, MultiArrayDimension,
                          UInt64MultiArray)

from micros_rt.transports.dds.types import MalformedSampleError, dds_type_for, is_numpy_msg

VALUES = [k * 0.25 for k in range(-5, 1076)]  # float32-exact


def scan(ranges: Any, intensities: Any) -> Any:
    msg = LaserScan()
    msg.header.frame_id = "laser"
    msg.angle_min, msg.angle_max = -2.25, 2.25
    msg.ranges, msg.intensities = ranges, intensities
    return msg


def wire(msg: Any) -> bytes:
    return bytes(dds_type_for(LaserScan).encode(msg))


def test_numpy_and_array_values_encode_to_the_bytes_of_the_list() -> None:
    expect = wire(scan(VALUES, VALUES[:10]))
    f32 = numpy.array(VALUES, dtype=numpy.float32)
    assert wire(scan(f32, f32[:10])) == expect
    assert wire(scan(array.array("f", VALUES), array.array("f", VALUES[:10]))) == expect
    assert wire(scan(tuple(VALUES), VALUES[:10])) == expect
    # the same bytes as cyclonedds' own serializer
    t = dds_type_for(LaserScan)
    assert t.idl_class.deserialize(expect).serialize() == expect


@pytest.mark.parametrize("cls, values, blocks", [
    # 8-byte items after an empty and a one-element dim: padding to 8 from byte 4 either way
    (Float64MultiArray, [1.5, -2.0, 1e300], [numpy.array([1.5, -2.0, 1e300]), array.array("d", [1.5, -2.0, 1e300])]),
    (Int64MultiArray, [2 ** 62, -1, 0], [numpy.array([2 ** 62, -1, 0], dtype="<i8"), array.array("q", [2 ** 62, -1, 0]),
                                         array.array("l", [2 ** 62, -1, 0])]),
    (UInt64MultiArray, [2 ** 64 - 1, 5], [numpy.array([2 ** 64 - 1, 5], dtype=numpy.uint64),
                                          array.array("Q", [2 ** 64 - 1, 5])]),
    (Int32MultiArray, [-(2 ** 31), 7], [numpy.array([-(2 ** 31), 7], dtype=numpy.int32), array.array("i", [-(2 ** 31), 7])]),
    (Int16MultiArray, [-300, 300, 1], [numpy.array([-300, 300, 1], dtype=numpy.int16), array.array("h", [-300, 300, 1])]),
], ids=lambda v: getattr(v, "_type", None) or "")
def test_every_numeric_width_encodes_blocks_to_the_bytes_of_the_list(cls: Any, values: list[Any],
                                                                     blocks: list[Any]) -> None:
    t = dds_type_for(cls)
    for dims in ([], [MultiArrayDimension(label="x", size=len(values), stride=len(values))]):
        expect = bytes(t.encode(cls(data=values, layout=cls().layout.__class__(dim=dims, data_offset=3))))
        assert t.idl_class.deserialize(expect).serialize() == expect  # cyclonedds agrees on the layout
        for block in blocks:
            assert bytes(t.encode(cls(data=block, layout=cls().layout.__class__(dim=dims, data_offset=3)))) == expect
        assert dds_type_for(numpy_msg(cls)).decode(expect).data.tolist() == values


def test_values_of_another_dtype_are_converted_not_reinterpreted() -> None:
    expect = wire(scan(VALUES, VALUES[:10]))
    f64 = numpy.array(VALUES, dtype=numpy.float64)  # 8-byte floats for a float32[] field
    assert wire(scan(f64, array.array("d", VALUES[:10]))) == expect
    big = numpy.array(VALUES, dtype=">f4")  # right size, other byte order
    assert wire(scan(big, big[:10])) == expect
    strided = numpy.array(VALUES * 2, dtype=numpy.float32).reshape(2, -1)[:, :10].T.ravel()[::2]  # not contiguous
    assert not strided.flags.c_contiguous
    assert wire(scan([], strided)) == wire(scan([], strided.tolist()))
    ints = dds_type_for(Int32MultiArray)
    assert ints.encode(Int32MultiArray(data=numpy.array([1, -2, 3], dtype=numpy.int64))) == \
        ints.encode(Int32MultiArray(data=[1, -2, 3]))


def test_out_of_range_and_wrong_shapes_are_clear_errors() -> None:
    ints = dds_type_for(Int32MultiArray)
    with pytest.raises(genpy.SerializationError, match="cannot serialize std_msgs/Int32MultiArray"):
        ints.encode(Int32MultiArray(data=numpy.array([1, 2 ** 40], dtype=numpy.int64)))  # not wrapped to int32
    with pytest.raises(genpy.SerializationError, match="field ranges: a numpy array of 2 dimensions"):
        dds_type_for(LaserScan).encode(scan(numpy.zeros((3, 3), dtype=numpy.float32), []))
    with pytest.raises(genpy.SerializationError, match="fixed-size array needs 9 elements, got 8"):
        dds_type_for(Imu).encode(Imu(orientation_covariance=numpy.zeros(8)))


def test_numpy_msg_classes_decode_numeric_arrays_as_views_of_the_sample() -> None:
    assert is_numpy_msg(numpy_msg(LaserScan)) and not is_numpy_msg(LaserScan)
    data = wire(scan(VALUES, VALUES[:3]))
    back = dds_type_for(numpy_msg(LaserScan)).decode(data)
    assert isinstance(back, numpy_msg(LaserScan))
    assert back.ranges.dtype == numpy.float32 and back.ranges.tolist() == VALUES
    assert back.intensities.tolist() == VALUES[:3]
    assert back.ranges.base is data  # zero-copy: the array views the received bytes
    assert not back.ranges.flags.writeable  # as rospy's numpy_msg arrays from frombuffer
    assert (back.angle_min, back.header.frame_id) == (-2.25, "laser")
    plain = dds_type_for(LaserScan).decode(data)  # the plain class keeps ROS 1's tuples
    assert plain.ranges == tuple(VALUES)


def test_numpy_msg_decodes_fixed_nested_and_empty_arrays_like_rospy() -> None:
    imu = Imu(orientation_covariance=[float(k) for k in range(9)])
    back = dds_type_for(numpy_msg(Imu)).decode(dds_type_for(Imu).encode(imu))
    assert back.orientation_covariance.dtype == numpy.float64
    assert back.orientation_covariance.tolist() == list(range(9))
    assert back.linear_acceleration_covariance.tolist() == [0.0] * 9
    # numeric arrays inside arrays of messages, as genpy's numpy deserializer does
    cloud = PointCloud(channels=[ChannelFloat32(name="i", values=[1.5, 2.5]), ChannelFloat32(name="e", values=[])])
    back = dds_type_for(numpy_msg(PointCloud)).decode(dds_type_for(PointCloud).encode(cloud))
    assert [c.values.tolist() for c in back.channels] == [[1.5, 2.5], []]
    assert all(isinstance(c.values, numpy.ndarray) for c in back.channels)
    # uint8[] stays bytes in a numpy_msg class too (genpy treats it as a string)
    img = dds_type_for(numpy_msg(Image)).decode(dds_type_for(Image).encode(Image(data=b"\x01\x02\x03")))
    assert img.data == b"\x01\x02\x03"
    wide = dds_type_for(numpy_msg(Int64MultiArray)).decode(
        dds_type_for(Int64MultiArray).encode(Int64MultiArray(data=[2 ** 62, -1])))
    assert wide.data.dtype == numpy.int64 and wide.data.tolist() == [2 ** 62, -1]


def test_numpy_msg_reads_big_endian_samples_and_refuses_truncated_ones() -> None:
    t = dds_type_for(numpy_msg(Float64MultiArray))
    # layout: dim (empty sequence), data_offset, then data: 2 doubles, big endian, aligned to 8 from byte 4
    sample = b"\x00\x00\x00\x00" + struct.pack(">III", 0, 0, 2) + bytes(4) + struct.pack(">dd", 1.5, -2.0)
    data = t.decode(sample).data
    assert data.tolist() == [1.5, -2.0]
    assert data.dtype.isnative  # as rospy's arrays: republished over TCPROS, genpy writes their raw bytes
    good = dds_type_for(LaserScan).encode(scan(VALUES, []))
    with pytest.raises(MalformedSampleError, match="sensor_msgs/LaserScan"):
        dds_type_for(numpy_msg(LaserScan)).decode(bytes(good[:-400]))


def test_bool_arrays_take_numpy_bools_and_stay_lists_of_bool(monkeypatch: pytest.MonkeyPatch) -> None:
    # no installed message has a bool[] field: a generated one, found by name as installed ones are
    import warnings

    import genpy.dynamic
    import roslib.message

    classes = genpy.dynamic.generate_dynamic("micros_rt_test/Flags", "bool[] flags\nbool[2] pair\n")
    cls = classes["micros_rt_test/Flags"]
    real = roslib.message.get_message_class
    monkeypatch.setattr(roslib.message, "get_message_class",
                        lambda name, *a, **k: classes.get(name) or real(name, *a, **k))
    t = dds_type_for(cls)
    expect = bytes(t.encode(cls(flags=[True, False, True], pair=[False, True])))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy 1.24 deprecates packing a numpy bool as an integer; 2.x refuses
        assert bytes(t.encode(cls(flags=numpy.array([True, False, True]), pair=numpy.array([False, True])))) == expect
    back = dds_type_for(numpy_msg(cls)).decode(expect)
    assert back.flags == [True, False, True] and back.pair == [False, True]  # as genpy's numpy deserializer
