"""The ordered disk buffer and run-time message classes (no broker)."""

from __future__ import annotations

import io
import os
from pathlib import Path

from micros_rt.transports.mqtt import codec
from micros_rt.bridges.mqtt.bridge import _message_class, is_connected_service_class
from micros_rt.transports.mqtt.client import DiskBuffer, properties_from_dict, properties_to_dict


def test_disk_buffer_keeps_order_and_size(tmp_path: Path) -> None:
    buf = DiskBuffer(str(tmp_path / "b"), 3)
    assert [buf.put("t", bytes([i]), 1, False) for i in range(5)] == [True, True, True, False, False]
    assert sorted(os.listdir(tmp_path / "b")) == ["000000000000.mqtt", "000000000001.mqtt", "000000000002.mqtt"]
    again = DiskBuffer(str(tmp_path / "b"), 3)        # a restarted bridge finds what is left
    got = []
    while (item := again.pop()) is not None:
        got.append(item[1])
    assert got == [b"\x00", b"\x01", b"\x02"] and len(again) == 0 and os.listdir(tmp_path / "b") == []


def test_disk_buffer_reports_age(tmp_path: Path) -> None:
    buf = DiskBuffer(str(tmp_path), 10, max_age=1.0)
    buf.put("a/b", b"payload\nwith newline", 2, True, {"user": [["micros_rt", "g|/n"]], "expiry": 9})
    topic, payload, qos, retain, age, props = buf.pop()  # type: ignore[misc]
    assert (topic, payload, qos, retain) == ("a/b", b"payload\nwith newline", 2, True) and 0 <= age < 5
    restored = properties_from_dict(props, age=2.5)
    assert properties_to_dict(restored) == {
        "user": [["micros_rt", "g|/n"]], "expiry": 6}


def test_type_not_installed_is_built_from_the_announced_definition() -> None:
    definition = "string name\nfloat64[] values\nPoint p\n" + "=" * 80 + "\nMSG: my_pkg/Point\nint32 x\n"
    import genpy.dynamic

    reference = genpy.dynamic.generate_dynamic("my_pkg/Reading", definition)["my_pkg/Reading"]
    cls = _message_class(codec.RosMsgType(reference._md5sum, "my_pkg/Reading", definition))
    msg = cls(name="r", values=[1.0, 2.5])
    msg.p.x = 7
    buf = io.BytesIO()
    msg.serialize(buf)
    back = cls().deserialize(buf.getvalue())
    assert (back.name, list(back.values), back.p.x) == ("r", [1.0, 2.5], 7)


def test_installed_class_is_used_when_the_md5_matches() -> None:
    from std_msgs.msg import String

    assert _message_class(codec.RosMsgType.of(String)) is String


def test_is_connected_has_mqtt_client_md5() -> None:
    srv = is_connected_service_class(codec.WireGeneration.V1)
    assert srv._type == "mqtt_client/IsConnected" and srv._md5sum == "e0cdaf65159c7f3563426650fb8d3f64"
    assert srv._response_class(connected=True).connected is True
