"""The microcontroller link's wire format, byte for byte (seed 003): datagrams and serial datagrams.

Fixtures are written out by hand from the MessagePack spec and the CRC32 check value, not produced by
the code under test. The CVRA_* fixtures are the bytes CVRA's own implementation produces: cvra_rpc's
``message.encode``/``service_call.encode_call`` and ``serial_datagram.encode`` from cvra/robot-software at
commit a5061d965ffeeca5f8466b65f7961a8b3951ac1f (the parent of 2e463e01b977, which removed them), paths
lib/simplerpc/python/cvra_rpc/{message,service_call}.py and lib/serial-datagram/python/serial_datagram.py,
run on this venv's msgpack (it reports version (1, 2, 4); their ``encoding='ascii'`` changed to ``raw=False``, nothing else); their code is not
part of this repository.
"""

from __future__ import annotations

from typing import Any

import os
import random

import genpy
import msgpack
import pytest
import roslib.message
from geometry_msgs.msg import Twist, Vector3
from sensor_msgs.msg import Imu
from std_msgs.msg import Duration, Header, String, UInt8MultiArray
from std_srvs.srv import SetBool, SetBoolRequest, TriggerResponse

from micros_rt.transports.mcu import wire
from micros_rt.transports.mcu.errors import WireError

F0 = "cb" + "00" * 8  # float64 0.0

TWIST_DATAGRAM = bytes.fromhex(
    "a7636d645f76656c"                                   # "cmd_vel"
    "82"                                                 # map of 2
    "a66c696e656172" "83" "a178cb3ff8000000000000" f"a179{F0}" f"a17a{F0}"   # linear: {x: 1.5, y: 0, z: 0}
    "a7616e67756c6172" "83" f"a178{F0}" f"a179{F0}" "a17acbbfe0000000000000"  # angular: {x: 0, y: 0, z: -0.5}
)

HEADER_DATAGRAM = bytes.fromhex(
    "a3686472" "83" "a3736571" "07" "a57374616d70" "9201cd01f4" "a86672616d655f6964" "a161")


def twist() -> Twist:
    return Twist(linear=Vector3(1.5, 0.0, 0.0), angular=Vector3(0.0, 0.0, -0.5))


def test_twist_datagram_is_name_then_map_of_nested_maps() -> None:
    readme = wire.WireForm.README
    assert wire.encode_datagram("cmd_vel", wire.codec_for(Twist).to_wire(twist()), form=readme) == TWIST_DATAGRAM
    # the map form is the same name and map inside one array of two
    assert wire.encode_datagram("cmd_vel", wire.codec_for(Twist).to_wire(twist()), form=wire.WireForm.MAP) \
        == b"\x92" + TWIST_DATAGRAM
    # the default (CVRA's final form): [name, [linear, angular]], nested messages as arrays in definition order
    assert wire.encode_datagram("cmd_vel", wire.codec_for(Twist).to_wire(twist())) == bytes.fromhex(
        "92" "a7636d645f76656c" "92" "93" "cb3ff8000000000000" f"{F0}{F0}" "93" f"{F0}{F0}" "cbbfe0000000000000")


def test_time_is_secs_nsecs_array() -> None:
    msg = Header(seq=7, stamp=genpy.Time(1, 500), frame_id="a")
    assert wire.encode_datagram("hdr", wire.codec_for(Header).to_wire(msg), form=wire.WireForm.README) \
        == HEADER_DATAGRAM
    name, body = wire.split_datagram(HEADER_DATAGRAM)
    assert name == "hdr" and wire.codec_for(Header).from_args(body) == msg


def test_negative_duration_and_uint8_array_as_bin() -> None:
    dur = wire.encode_datagram("d", wire.codec_for(Duration).to_wire(Duration(data=genpy.Duration(-1, 5))))
    assert dur == bytes.fromhex("92" "a164" "92ff05")   # one field: its value bare
    arr = UInt8MultiArray(data=b"\x01\x02\x03")
    got = wire.encode_datagram("u", wire.codec_for(UInt8MultiArray).to_wire(arr), form=wire.WireForm.MAP)
    assert got == bytes.fromhex("92" "a175" "82" "a66c61796f7574" "82" "a364696d" "90" "ab646174615f6f6666736574" "00"
                                "a464617461" "c403010203")
    assert wire.codec_for(UInt8MultiArray).from_args(wire.split_datagram(got)[1]).data == b"\x01\x02\x03"
    final = wire.encode_datagram("u", wire.codec_for(UInt8MultiArray).to_wire(arr))
    assert final == bytes.fromhex("92" "a175" "92" "92" "90" "00" "c403010203")
    assert wire.codec_for(UInt8MultiArray).from_args(wire.split_datagram(final)[1]) == arr


def test_array_form_is_accepted_with_nested_maps_or_arrays() -> None:
    as_arrays = msgpack.packb(["cmd_vel", [1.5, 0, 0], [0, 0, -0.5]])
    as_maps = msgpack.packb(["cmd_vel", {"x": 1.5, "y": 0, "z": 0}, {"x": 0, "y": 0, "z": -0.5}])
    cvra = msgpack.packb(["cmd_vel", {"linear": {"x": 1.5, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": -0.5}}])
    for data in (as_arrays, as_maps, cvra, TWIST_DATAGRAM):
        name, body = wire.split_datagram(data)
        assert name == "cmd_vel" and wire.codec_for(Twist).from_args(body) == twist()


def test_map_form_round_trip_of_a_full_imu() -> None:
    msg = Imu()
    msg.header.stamp = genpy.Time(1_700_000_000, 123)
    msg.header.frame_id = "imu_link"
    msg.orientation.w = 1.0
    msg.orientation_covariance = [0.01 * i for i in range(9)]
    msg.linear_acceleration.z = 9.81
    for form in wire.WireForm:
        data = wire.encode_datagram("imu", wire.codec_for(Imu).to_wire(msg), form=form)
        name, body = wire.split_datagram(data)
        assert name == "imu" and wire.codec_for(Imu).from_args(body) == msg, form


@pytest.mark.parametrize("data, kind", [
    (b"\xc1\x00", "not_msgpack"),                                       # 0xc1 is never used
    (b"\xa3im", "not_msgpack"),                                         # truncated string
    (b"", "not_msgpack"),
    (msgpack.packb(42), "bad_shape"),
    (msgpack.packb(1) + msgpack.packb({}), "bad_shape"),                # a number then a map
    (msgpack.packb("a") + msgpack.packb({}) + msgpack.packb(1), "bad_shape"),
])
def test_malformed_datagrams_are_refused_by_kind(data: bytes, kind: str) -> None:
    with pytest.raises(WireError) as info:
        wire.split_datagram(data)
    assert info.value.kind == kind


@pytest.mark.parametrize("body, kind, words", [
    ({"linear": {"x": 1.0, "y": 0.0}, "angular": {"x": 0, "y": 0, "z": 0}}, "missing_field", "'linear.z'"),
    ({"linear": {"x": "fast", "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}, "bad_field",
     "'linear.x' should be a number (float64), got the string 'fast'"),
    ({"linear": {"x": 0, "y": 0, "z": 0}, "angular": [0, 0]}, "missing_field", "needs 3 fields"),
    ({"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}, "spin": 1}, "unknown_field",
     "no field the string 'spin'"),
    ({"linear": 5, "angular": {"x": 0, "y": 0, "z": 0}}, "bad_field", "'linear' should be a geometry_msgs/Vector3"),
])
def test_bad_fields_name_the_field(body: Any, kind: str, words: str) -> None:
    with pytest.raises(WireError) as info:
        wire.codec_for(Twist).from_wire(body)
    assert info.value.kind == kind and words in str(info.value)


def test_integer_ranges_bools_and_fixed_arrays_are_checked() -> None:
    codec = wire.codec_for(Header)
    with pytest.raises(WireError, match="uint32"):
        codec.from_wire({"seq": -1, "stamp": [0, 0], "frame_id": ""})
    with pytest.raises(WireError, match="nsecs 0..999999999"):
        codec.from_wire({"seq": 0, "stamp": [0, 1_000_000_000], "frame_id": ""})
    with pytest.raises(WireError, match="exactly 9"):
        body = wire.codec_for(Imu).to_wire(Imu())
        body["orientation_covariance"] = [0.0] * 8
        wire.codec_for(Imu).from_wire(body)
    assert wire.codec_for(SetBool._request_class).from_wire([1]).data is True   # firmware's 0/1 bools
    with pytest.raises(WireError):
        wire.codec_for(SetBool._request_class).from_wire([2])


def test_bad_values_refused_when_encoding_like_genpy() -> None:
    with pytest.raises(genpy.SerializationError, match="'data'"):
        wire.codec_for(String).to_wire(String(data=123))


# --------------------------------------------------------------------------- serial datagrams


def test_serial_datagram_appends_big_endian_crc32_and_end() -> None:
    # CRC32("123456789") is the standard check value 0xCBF43926
    assert wire.frame(b"123456789") == b"123456789" + bytes.fromhex("cbf43926") + b"\xc0"


def test_serial_datagram_escapes_payload_and_crc() -> None:
    assert wire.frame(b"\xc0\xdb\x01") == bytes.fromhex("dbdc" "dbdd" "01" "7b256310" "c0")
    # the CRC of 00 07 86 is b4 db 69 c0: its own 0xDB and 0xC0 are escaped too
    assert wire.frame(bytes.fromhex("000786")) == bytes.fromhex("000786" "b4" "dbdd" "69" "dbdc" "c0")
    assert wire.unframe(bytes.fromhex("000786b4dbdd69dbdc")) == bytes.fromhex("000786")


def test_service_request_is_framed_name_and_params() -> None:
    req = SetBoolRequest(data=True)
    fields = wire.codec_for(SetBool._request_class).to_wire(req)
    mid = wire.encode_request("set_mode", fields, form=wire.WireForm.MID2015)
    assert mid == bytes.fromhex("92" "a87365745f6d6f6465" "c3" "b3779734" "c0")
    assert wire.encode_request("set_mode", fields) == mid     # final, one field: the same bytes
    assert wire.decode_request(mid[:-1]) == ("set_mode", [True])
    assert wire.codec_for(SetBool._request_class).from_request([True]) == req
    readme = wire.encode_request("set_mode", fields, form=wire.WireForm.README)  # two objects in one frame
    assert readme == bytes.fromhex("a87365745f6d6f6465" "81a464617461c3" "b308dbdced" "c0")
    assert wire.decode_request(readme[:-1]) == ("set_mode", [{"data": True}])


def test_service_response_is_a_plain_map() -> None:
    fields = wire.codec_for(TriggerResponse).to_wire(TriggerResponse(True, "ok"))
    data = wire.encode_response(fields, form=wire.WireForm.MAP)
    assert data == bytes.fromhex("82" "a773756363657373" "c3" "a76d657373616765" "a26f6b")
    assert wire.codec_for(TriggerResponse).from_answer(wire.decode_response(data)).response == TriggerResponse(True, "ok")
    final = wire.encode_response(fields)            # as CVRA's handlers answer: the fields as an array
    assert final == bytes.fromhex("92" "c3" "a26f6b")
    assert wire.codec_for(TriggerResponse).from_answer(wire.decode_response(final)).response == TriggerResponse(True, "ok")


@pytest.mark.parametrize("body, kind", [
    (bytes.fromhex("313233343536373839cbf43927"), "bad_crc"),
    (bytes.fromhex("3132db01cbf43926"), "bad_escape"),
    (bytes.fromhex("3132db"), "bad_escape"),
    (bytes.fromhex("0102"), "short_frame"),
])
def test_bad_frames_by_kind(body: bytes, kind: str) -> None:
    with pytest.raises(WireError) as info:
        wire.unframe(body)
    assert info.value.kind == kind


def test_frame_reader_waits_for_end_and_bounds_the_size() -> None:
    reader = wire.FrameReader(16)
    assert reader.feed(b"\xc0\xc0abc") is None          # leading END bytes are skipped
    assert reader.feed(b"def\xc0trailing") == b"abcdef"
    with pytest.raises(WireError) as info:
        wire.FrameReader(16).feed(b"x" * 17)
    assert info.value.kind == "frame_too_long"


def test_fuzzed_datagrams_and_frames_only_ever_raise_wire_error() -> None:
    rnd = random.Random(12)
    imu = wire.codec_for(Imu)
    request = wire.codec_for(SetBool._request_class)
    seeds = [wire.encode_datagram("imu", imu.to_wire(Imu())), bytes(msgpack.packb(["imu", *imu.to_wire_list(Imu())])),
             wire.encode_datagram("imu", imu.to_wire(Imu()), form=wire.WireForm.README),
             wire.encode_request("set_mode", {"data": True}), CVRA_CALL_SET_MODE_LIST,
             wire.encode_request("set_mode", {"data": True}, form=wire.WireForm.README),
             bytes.fromhex("a3696d7581910102")]  # a map key that is an array
    kinds: dict[str, int] = {}
    for i in range(20_000):
        data = bytearray(os.urandom(rnd.randint(0, 40)) if i % 5 == 0 else rnd.choice(seeds))
        for _ in range(rnd.randint(0, 3) if i % 5 else 0):
            data[rnd.randrange(len(data))] = rnd.randrange(256)
        try:
            if data.endswith(b"\xc0"):
                name, params = wire.decode_request(bytes(data[:-1]))
                request.from_request(params)
            else:
                name, body = wire.split_datagram(bytes(data))
                imu.from_args(body)
        except WireError as exc:
            kinds[exc.kind] = kinds.get(exc.kind, 0) + 1
    assert {"not_msgpack", "bad_shape", "bad_crc"} <= set(kinds)


def test_numpy_and_array_values_go_out_as_the_list_would() -> None:
    import array

    import numpy

    msg = Imu()
    msg.orientation_covariance = [0.5 * i for i in range(9)]
    expect = wire.codec_for(Imu).to_wire(msg)
    msg.orientation_covariance = numpy.array([0.5 * i for i in range(9)])  # rospy.numpy_msg style
    assert wire.codec_for(Imu).to_wire(msg) == expect
    msg.orientation_covariance = array.array("d", [0.5 * i for i in range(9)])
    assert wire.codec_for(Imu).to_wire(msg) == expect
    msg.orientation_covariance = numpy.zeros((3, 3))
    with pytest.raises(genpy.SerializationError, match="orientation_covariance"):
        wire.codec_for(Imu).to_wire(msg)


# --------------------------------------------------------------------------- CVRA's cvra_rpc, byte for byte
# Each fixture is what CVRA's code writes for the call in its comment (see the module docstring for where
# the code is). The shapes of their own tests (test_messages.py, test_service_call.py): encode("foo"),
# encode("foo", [1, 2, 3]), encode_call("bar", [10]), a float packed single (1. + 1e-8 reads back as 1.0).

CVRA_CHATTER = bytes.fromhex("92" "a763686174746572" "81" "a464617461" "a26869")     # encode("chatter", {"data": "hi"})
CVRA_SPEED = bytes.fromhex("92" "a57370656564" "81" "a464617461" "ca3fc00000")       # encode("speed", {"data": 1.5})
CVRA_SPEED_01 = bytes.fromhex("92" "a57370656564" "81" "a464617461" "ca3dcccccd")    # encode("speed", {"data": 0.1})
CVRA_NO_ARGS = bytes.fromhex("92" "a3666f6f" "c0")                                   # encode("foo")
CVRA_POSITIONAL_ARGS = bytes.fromhex("92" "a3666f6f" "93010203")                     # encode("foo", [1, 2, 3])
CVRA_TWIST = bytes.fromhex(                        # encode("cmd_vel", {"linear": {x: 1.5, ..}, "angular": {.., z: -0.5}})
    "92" "a7636d645f76656c" "82"
    "a66c696e656172" "83" "a178ca3fc00000" "a179ca00000000" "a17aca00000000"
    "a7616e67756c6172" "83" "a178ca00000000" "a179ca00000000" "a17acabf000000")
CVRA_CALL_RESET_X = bytes.fromhex("92" "a57265736574" "81a17801" "77864a51" "c0")    # encode_call("reset", {"x": 1})
CVRA_CALL_SET_MODE_LIST = bytes.fromhex("92" "a87365745f6d6f6465" "91c3" "79e5" "dbdc" "73" "c0")  # (.., [True])
CVRA_CALL_SET_MODE_MAP = bytes.fromhex("92" "a87365745f6d6f6465" "81a464617461c3" "efbdb857" "c0")  # (.., {"data": True})
CVRA_CALL_NO_PARAMS = bytes.fromhex("92" "a57265736574" "dbdc" "ed8dbc20" "c0")      # encode_call("reset", None)
CVRA_CALL_BAR_10 = bytes.fromhex("92" "a3626172" "910a" "c521811b" "c0")            # encode_call("bar", [10])


def cvra_decode(data: bytes) -> tuple[Any, Any]:
    """What cvra_rpc's message.decode returns: the first object of the datagram, as (obj[0], obj[1])."""
    unpacker = msgpack.Unpacker(raw=False)
    unpacker.feed(data)
    first = next(unpacker)
    return first[0], first[1]


def cvra_decode_call(frame: bytes) -> tuple[Any, Any]:
    """What cvra_rpc's service_call.decode_call returns (serial_datagram.decode, then as cvra_decode)."""
    return cvra_decode(wire.unframe(frame[:-1]))


def test_cvra_topic_datagrams_read_as_their_messages() -> None:
    from std_msgs.msg import Empty, Float32, Float64
    name, body = wire.split_datagram(CVRA_CHATTER)      # read as the positional form before: "should be a string"
    assert (name, wire.codec_for(String).from_args(body)) == ("chatter", String(data="hi"))
    name, body = wire.split_datagram(CVRA_SPEED_01)     # float32 on the wire, for a float64 field too
    assert wire.codec_for(Float64).from_args(body).data == pytest.approx(0.1, abs=1e-8)
    assert wire.codec_for(Float32).from_args(body).data == pytest.approx(0.1, abs=1e-8)
    name, body = wire.split_datagram(CVRA_TWIST)
    assert (name, wire.codec_for(Twist).from_args(body)) == ("cmd_vel", twist())
    assert wire.split_datagram(CVRA_NO_ARGS) == ("foo", [None])   # no arguments: an empty message
    assert wire.codec_for(Empty).from_args(wire.split_datagram(CVRA_NO_ARGS)[1]) == Empty()
    assert wire.split_datagram(CVRA_POSITIONAL_ARGS) == ("foo", [[1, 2, 3]])  # one positional field, an array


def test_written_topic_datagrams_are_cvra_bytes_and_read_by_cvra() -> None:
    from std_msgs.msg import Float32, Float64
    m = wire.WireForm.MAP
    assert wire.encode_datagram("chatter", wire.codec_for(String).to_wire(String(data="hi")), form=m) == CVRA_CHATTER
    # a float32 field is written as MessagePack float32, as CVRA's use_single_float=True does
    assert wire.encode_datagram("speed", wire.codec_for(Float32).to_wire(Float32(data=1.5)), form=m) == CVRA_SPEED
    assert wire.encode_datagram("speed", wire.codec_for(Float32).to_wire(Float32(data=0.1)), form=m) == CVRA_SPEED_01
    # a float64 field stays float64 (CVRA's decoder reads either)
    f64 = wire.encode_datagram("speed", wire.codec_for(Float64).to_wire(Float64(data=0.1)), form=m)
    assert f64 == bytes.fromhex("92" "a57370656564" "81" "a464617461" "cb3fb999999999999a")
    assert cvra_decode(f64) == ("speed", {"data": 0.1})
    # CVRA's decoder read the README form as name 'c', args 'h'; the default form it reads as sent
    readme = wire.encode_datagram("chatter", {"data": "hi"}, form=wire.WireForm.README)
    assert cvra_decode(readme) == ("c", "h")
    assert cvra_decode(wire.encode_datagram("chatter", {"data": "hi"}, form=m)) == ("chatter", {"data": "hi"})
    assert cvra_decode(wire.encode_datagram("chatter", {"data": "hi"})) == ("chatter", "hi")   # final: bare


def test_float32_fields_are_float32_also_in_arrays_and_nested() -> None:
    from sensor_msgs.msg import LaserScan
    scan = LaserScan(angle_min=-1.5, ranges=[0.5, 2.0], intensities=[])
    data = wire.encode_datagram("scan", wire.codec_for(LaserScan).to_wire(scan), form=wire.WireForm.MAP)
    assert bytes.fromhex("a9616e676c655f6d696e" "cabfc00000") in data        # angle_min: float32 -1.5
    assert bytes.fromhex("a672616e676573" "92" "ca3f000000" "ca40000000") in data  # ranges: [0.5, 2.0] as float32
    assert b"\xcb" not in data                                             # no float64 anywhere
    assert wire.codec_for(LaserScan).from_args(wire.split_datagram(data)[1]) == scan
    from std_msgs.msg import Float32
    with pytest.raises(genpy.SerializationError, match="float32's range"):
        wire.codec_for(Float32).to_wire(Float32(data=1e40))


def test_cvra_service_calls_read_as_requests() -> None:
    from std_srvs.srv import Trigger
    set_mode = wire.codec_for(SetBool._request_class)
    for frame in (CVRA_CALL_SET_MODE_LIST, CVRA_CALL_SET_MODE_MAP):
        name, rest = wire.decode_request(frame[:-1])
        assert name == "set_mode" and set_mode.from_request(rest) == SetBoolRequest(data=True)
    name, rest = wire.decode_request(CVRA_CALL_NO_PARAMS[:-1])
    assert name == "reset" and wire.codec_for(Trigger._request_class).from_request(rest) == Trigger._request_class()
    # a params map naming a field the request does not have is refused by name, not read positionally
    name, rest = wire.decode_request(CVRA_CALL_RESET_X[:-1])
    with pytest.raises(WireError, match="no field the string 'x'"):
        wire.codec_for(Trigger._request_class).from_request(rest)


def test_requests_in_both_forms_with_several_and_one_nested_field() -> None:
    logger = wire.codec_for(roslib.message.get_service_class("roscpp/SetLoggerLevel")._request_class)
    want = logger.data_class(logger="ros", level="debug")
    cvra_map = wire.decode_request(wire.encode_request("lvl", {"logger": "ros", "level": "debug"},
                                                       form=wire.WireForm.MAP)[:-1])[1]
    cvra_list = [["ros", "debug"]]                                  # encode_call("lvl", ["ros", "debug"])
    mid = wire.decode_request(wire.encode_request("lvl", logger.to_wire(want), form=wire.WireForm.MID2015)[:-1])[1]
    assert mid == ["ros", "debug"]
    readme = wire.decode_request(wire.encode_request("lvl", logger.to_wire(want), form=wire.WireForm.README)[:-1])[1]
    assert readme == [{"logger": "ros", "level": "debug"}]
    for rest in (cvra_map, cvra_list, mid, readme):
        assert logger.from_request(rest) == want
    # CVRA's final call written by default: [name, [fields...]], which CVRA's decode_call gives its handler as a list
    assert cvra_decode_call(wire.encode_request("lvl", logger.to_wire(want))) == ("lvl", ["ros", "debug"])
    assert cvra_decode_call(wire.encode_request("reset", {})) == ("reset", None)
    # one field that is a message: CVRA's {camera_info: {...}} and the README's [name, {...}] both read
    cam_class = roslib.message.get_service_class("sensor_msgs/SetCameraInfo")._request_class
    cam = wire.codec_for(cam_class)
    req = cam_class()
    req.camera_info.width = 640
    inner = cam.to_wire(req)["camera_info"]
    assert cam.from_request([{"camera_info": inner}]) == req      # CVRA's form
    assert cam.from_request([inner]) == req                       # README's [name, field1]
    with pytest.raises(WireError, match="'camera_info.width'"):
        cam.from_request([{"camera_info": {**inner, "width": "wide"}}])  # CVRA's error when neither reads


def test_cvra_test_shapes_both_directions() -> None:
    # their test_decoding_method / test_correct_callback_called: encode_call("bar", [10]) is [name, [10]]
    assert wire.decode_request(CVRA_CALL_BAR_10[:-1]) == ("bar", [[10]])
    assert wire.codec_for(SetBool._request_class).from_request([[1]]) == SetBoolRequest(data=True)
    # ours, read by their decode_call: the only field bare (final), or the request's fields as one map (map form)
    assert cvra_decode_call(wire.encode_request("set_mode", {"data": True})) == ("set_mode", True)
    assert wire.encode_request("set_mode", {"data": True}, form=wire.WireForm.MAP) == CVRA_CALL_SET_MODE_MAP
    # their single-float check: 1. + 1e-8 written into a float32 field reads back as 1.0
    from std_msgs.msg import Float32
    data = wire.encode_datagram("foo", wire.codec_for(Float32).to_wire(Float32(data=1.0 + 1e-8)))
    assert cvra_decode(data) == ("foo", 1.0)
    # answers: as their handlers answer (an array of the fields), or a plain map in the map form
    assert msgpack.unpackb(wire.encode_response({"success": True, "message": "ok"})) == [True, "ok"]
    assert msgpack.unpackb(wire.encode_response({"success": True, "message": "ok"}, form=wire.WireForm.MAP)) == {
        "success": True, "message": "ok"}
