"""Services without processes: the srv mapping and its CDR bytes (as rclpy's serialize_message writes them),
handler return values, names, the helper's environment and its frame format. No ROS master, no DDS."""

from __future__ import annotations

import os
import socket
import struct
import threading
from typing import Any, Dict, List, Tuple

import pytest
import rospy
from std_msgs.msg import String
from std_srvs.srv import Empty, SetBool, Trigger

from micros_rt.exceptions import MicrosRtError
from micros_rt.services import ServiceError, ServiceTimeoutError, ServiceUnavailableError, dds_service_topics
from micros_rt.services import gateway as gw
from micros_rt.services.mapping import check_srv_class, ros2_service_type, srv_mapping
from micros_rt.services.server import as_response


def test_setbool_request_is_the_bytes_rclpy_writes() -> None:
    # rclpy: serialize_message(SetBool.Request(data=True)) == b"\x00\x01\x00\x00\x01"
    m = srv_mapping(SetBool)
    assert m.encode_request(SetBool._request_class(data=True)) == b"\x00\x01\x00\x00\x01"
    assert m.decode_request(b"\x00\x01\x00\x00\x01").data is True


def test_response_with_a_string_round_trips() -> None:
    m = srv_mapping(SetBool)
    data = m.encode_response(SetBool._response_class(success=True, message="héllo"))
    # bool, then the string's length (with its NUL) aligned to 4, UTF-8 bytes and NUL
    assert data == b"\x00\x01\x00\x00" + b"\x01\x00\x00\x00" + struct.pack("<I", 7) + "héllo".encode() + b"\x00"
    back = m.decode_response(data)
    assert (back.success, back.message) == (True, "héllo")


def test_empty_structs_carry_ros2s_placeholder_byte() -> None:
    # ROS 2 gives an empty struct a uint8 structure_needs_at_least_one_member: rclpy writes 5 bytes
    trigger = srv_mapping(Trigger)
    assert trigger.encode_request(Trigger._request_class()) == b"\x00\x01\x00\x00\x00"
    assert isinstance(trigger.decode_request(b"\x00\x01\x00\x00\x00"), Trigger._request_class)
    empty = srv_mapping(Empty)
    assert empty.encode_response(Empty._response_class()) == b"\x00\x01\x00\x00\x00"


def test_names_and_types_as_ros2_has_them() -> None:
    assert ros2_service_type("std_srvs/SetBool") == "std_srvs/srv/SetBool"
    assert srv_mapping(SetBool).ros2_type == "std_srvs/srv/SetBool"
    assert dds_service_topics("/robot/set_flag", "std_srvs/SetBool") == {
        "request_topic": "rq/robot/set_flagRequest", "reply_topic": "rr/robot/set_flagReply",
        "request_type": "std_srvs::srv::dds_::SetBool_Request_",
        "response_type": "std_srvs::srv::dds_::SetBool_Response_"}


@pytest.mark.parametrize("bad", [String, SetBool._request_class, "std_srvs/SetBool", None])
def test_srv_class_must_be_a_service_class(bad: Any) -> None:
    with pytest.raises(TypeError, match="srv_class must be a ROS service class"):
        check_srv_class(bad)


def test_handler_results_as_rospy_takes_them() -> None:
    response = SetBool._response_class
    assert as_response(response(True, "a"), response).message == "a"
    assert as_response({"success": True, "message": "b"}, response).message == "b"
    assert as_response((True, "c"), response).message == "c"
    assert as_response([False, "d"], response).success is False
    with pytest.raises(TypeError, match="returned None"):
        as_response(None, response)
    with pytest.raises(TypeError, match="returned a std_msgs/String"):
        as_response(String("x"), response)
    with pytest.raises(TypeError, match="not a std_srvs/SetBoolResponse"):
        as_response(42, response)


def test_errors_are_micros_rt_and_rospy_errors() -> None:
    for cls in (ServiceError, ServiceTimeoutError, ServiceUnavailableError):
        assert issubclass(cls, MicrosRtError) and issubclass(cls, rospy.ServiceException)
    assert issubclass(ServiceTimeoutError, rospy.ROSException)  # as rospy.wait_for_service's timeout


def test_helper_node_names_are_valid_ros2_names() -> None:
    assert gw._ros2_node_name("/robot/talker_123") == "robot_talker_123_services"
    assert gw._ros2_node_name("/9lives") == "n9lives_services"


def test_ros2_python_from_the_environment() -> None:
    assert gw.ros2_python({"MICROS_RT_ROS2_PYTHON": "/opt/ros2/bin/python3"}) == "/opt/ros2/bin/python3"


def test_helper_environment_on_loopback(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_IP", "127.0.0.1")
    monkeypatch.setenv("PYTHONPATH", "/usr/lib/python3/dist-packages")
    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE", raising=False)
    env, scratch = gw.Ros2Gateway._helper_env()
    try:
        assert "PYTHONPATH" not in env  # rospy's packages must not shadow ROS 2's (std_msgs, ...)
        assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        with open(env["FASTRTPS_DEFAULT_PROFILES_FILE"]) as f:
            profile = f.read()
        assert "<address>127.0.0.1</address>" in profile and "<useBuiltinTransports>false" in profile
    finally:
        for path in scratch:
            os.unlink(path)
    # a profile the user names wins
    monkeypatch.setenv("FASTRTPS_DEFAULT_PROFILES_FILE", "/etc/mine.xml")
    env, scratch = gw.Ros2Gateway._helper_env()
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/etc/mine.xml" and scratch == []


def test_gateway_against_a_scripted_helper(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """The micros_rt side of the frame protocol, with a stand-in helper (plain Python) at the other end."""
    script = tmp_path / "fake_helper.py"
    script.write_text('''
import json, socket, struct, sys
H = struct.Struct("<IBIH")
listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
listener.bind("\\0" + sys.argv[1])
listener.listen(1)
s, _ = listener.accept()
r = s.makefile("rb")
def send(op, cid, meta=None, body=b""):
    raw = json.dumps(meta).encode() if meta else b""
    s.sendall(H.pack(H.size - 4 + len(raw) + len(body), op, cid, len(raw)) + raw + body)
head = r.read(H.size)
n, op, cid, m = H.unpack(head)
hello = json.loads(r.read(n - (H.size - 4))[:m])
assert op == 24 and hello["node"] == "unit_services", (op, hello)
send(24, cid, {"pid": 1, "rmw": "fake"})
while True:
    head = r.read(H.size)
    if len(head) < H.size:
        break
    n, op, cid, m = H.unpack(head)
    rest = r.read(n - (H.size - 4))
    meta, body = (json.loads(rest[:m]) if m else {}), rest[m:]
    if op in (1, 3):
        send(20, cid, {"ok": True})
    elif op == 4:
        send(20, cid, {"ok": True, "ready": meta["name"] == "/up"})
    elif op == 5 and meta["name"] == "/up":
        send(21, cid, None, body[::-1])
    elif op == 5 and meta["name"] == "/fails":
        send(22, cid, {"error": "no ROS 2 server of /fails is available"})
    elif op == 5 and meta["name"] == "/serve":
        send(23, 77, {"name": "/served"}, b"ping")
    elif op == 7:
        send(21, 900 + cid, None, body)
''')
    monkeypatch.setattr(gw, "HELPER", script)
    import sys
    with gw.Ros2Gateway("/unit", python=sys.executable) as g:
        assert g.server_ready("/up", "x/srv/Y") and not g.server_ready("/down", "x/srv/Y")
        assert g.call("/up", "x/srv/Y", b"abc", 2.0) == b"cba"
        with pytest.raises(RuntimeError, match="no ROS 2 server of /fails"):
            g.call("/fails", "x/srv/Y", b"", 2.0)
        with pytest.raises(TimeoutError):
            g.call("/silent", "x/srv/Y", b"", 0.2)
        served: List[bytes] = []
        done = threading.Event()

        def handler(body: bytes) -> bytes:
            served.append(body)
            done.set()
            return b"pong"

        g.advertise("/served", "x/srv/Y", handler)
        with pytest.raises(TimeoutError):
            g.call("/serve", "x/srv/Y", b"", 0.2)  # makes the stand-in send a request of a ROS 2 client
        assert done.wait(2.0) and served == [b"ping"]
    assert g.closed
    g.close()  # harmless twice
