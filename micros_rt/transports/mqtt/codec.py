"""Payload formats on MQTT, pure functions (no broker, no ROS graph).

- mqtt_client's ROS 1 framing, in two generations (:class:`WireGeneration`):
  1.x (1.0-1.1): ``[1 | ros::Time (uint32 secs, uint32 nsecs) | message]`` when a timestamp is injected,
  ``[0 | message]`` otherwise; 2.x (2.0-2.3 for ROS 1): ``[ros::Time | message]`` or ``[message]``, no flag
  byte: the type announcement's ``stamped`` field says which. The message is in ROS 1 serialization.
- mqtt_client's type announcement: a serialized ``RosMsgType`` on ``mqtt_client/ros_msg_type/<mqtt_topic>``:
  1.x ``string md5, string name, string definition``; 2.x the same and ``bool stamped`` (one byte). The
  two are told apart by length.
- Primitive text: ``std_msgs`` primitives as their value; text from MQTT probed as bool, then integer,
  then float, then string (mqtt_client's order).
- JSON: every field (time as ``{"secs", "nsecs"}``, ``uint8[]`` as a list of numbers).

>>> encode_ros_payload(b"\\x02\\x00\\x00\\x00hi", wire=WireGeneration.V1)
b'\\x00\\x02\\x00\\x00\\x00hi'
>>> encode_ros_payload(b"\\x02\\x00\\x00\\x00hi", wire=WireGeneration.V2)
b'\\x02\\x00\\x00\\x00hi'
"""

from __future__ import annotations

import enum
import json
import math
import struct
from typing import Any, Dict, Optional, Tuple, Type

import genmsg.msgs  # type: ignore[import-untyped]
import genpy

from ...exceptions import MicrosRtError
from ...rostypes import FLOAT_TYPES, INT_RANGES, TIME_TYPES, parse_slot_type

__all__ = [
    "CodecError",
    "PRIMITIVE_TYPES",
    "ROS_MSG_TYPE_PREFIX",
    "RosMsgType",
    "WireGeneration",
    "decode_msg_type",
    "decode_ros_payload",
    "encode_msg_type",
    "encode_ros_payload",
    "json_to_msg",
    "msg_to_json",
    "msg_to_text",
    "probe_primitive",
    "text_to_msg",
    "RPC_REQUEST_PREFIX",
    "RPC_RESPONSE_PREFIX",
    "RPC_SHARE_GROUP",
    "decode_rpc_request",
    "decode_rpc_response",
    "encode_rpc_request",
    "encode_rpc_response",
]

#: mqtt_client's prefix of the retained topic that carries a data topic's ROS type.
ROS_MSG_TYPE_PREFIX = "mqtt_client/ros_msg_type/"

_TIME = struct.Struct("<II")
_LEN = struct.Struct("<I")

#: std_msgs types that travel as plain text (type name -> field type).
PRIMITIVE_TYPES: Dict[str, str] = {
    "std_msgs/String": "string", "std_msgs/Bool": "bool", "std_msgs/Char": "char",
    "std_msgs/UInt8": "uint8", "std_msgs/UInt16": "uint16", "std_msgs/UInt32": "uint32", "std_msgs/UInt64": "uint64",
    "std_msgs/Int8": "int8", "std_msgs/Int16": "int16", "std_msgs/Int32": "int32", "std_msgs/Int64": "int64",
    "std_msgs/Float32": "float32", "std_msgs/Float64": "float64",
}

_INT_RANGES: Dict[str, Tuple[int, int]] = INT_RANGES  # the one table (micros_rt.rostypes)


class CodecError(MicrosRtError, ValueError):
    """A payload that does not decode; the message says what was wrong with it."""


# ----------------------------------------------------------------------------- mqtt_client framing


class WireGeneration(enum.IntEnum):
    """Which mqtt_client wire a payload or type announcement follows (1.x: flag byte; 2.x: ``stamped``)."""

    V1 = 1
    V2 = 2

    @property
    def label(self) -> str:
        """As a person names it: ``1.x`` or ``2.x``."""
        return f"{int(self)}.x"


def encode_ros_payload(serialized: bytes, *, wire: WireGeneration, stamp: Optional[genpy.Time] = None) -> bytes:
    """mqtt_client's payload for an already serialized ROS 1 message (``stamp``: the injected time).

    2.x writes no flag byte: its readers learn from the type announcement (``stamped``) whether 8 stamp
    bytes lead, so a topic's announcement and payloads must agree."""
    head = _TIME.pack(int(stamp.secs), int(stamp.nsecs)) if stamp is not None else b""
    if wire is WireGeneration.V2:
        return head + serialized
    return (b"\x01" if stamp is not None else b"\x00") + head + serialized


def decode_ros_payload(payload: bytes, *, stamped: Optional[bool] = None) -> Tuple[Optional[genpy.Time], memoryview]:
    """(injected stamp or None, serialized message) of an mqtt_client payload.

    ``stamped`` is the peer's announced ``RosMsgType.stamped``: ``None`` for a 1.x peer (its payload starts
    with a flag byte), ``True``/``False`` for a 2.x peer (8 stamp bytes lead, or none)."""
    if stamped is None:
        if not payload:
            raise CodecError("empty payload (mqtt_client 1.x payloads start with a 0 or 1 byte)")
        flag = payload[0]
        if flag == 0:
            return None, memoryview(payload)[1:]
        if flag != 1:
            raise CodecError(f"first byte is {flag}, mqtt_client 1.x payloads start with 0 (no timestamp) or 1 "
                             "(timestamp)")
        return _stamp(payload, 1, "1.x"), memoryview(payload)[1 + _TIME.size:]
    if not stamped:
        return None, memoryview(payload)
    return _stamp(payload, 0, "2.x"), memoryview(payload)[_TIME.size:]


def _stamp(payload: bytes, pos: int, generation: str) -> genpy.Time:
    if len(payload) < pos + _TIME.size:
        raise CodecError(f"stamped mqtt_client {generation} payload of {len(payload)} bytes is shorter than its "
                         "8-byte timestamp")
    secs, nsecs = _TIME.unpack_from(payload, pos)
    if nsecs >= 1_000_000_000:
        raise CodecError(f"injected timestamp has {nsecs} nanoseconds (must be below 1e9)")
    return genpy.Time(secs, nsecs)


class RosMsgType:
    """mqtt_client's ``RosMsgType`` message: a type's md5, name and full definition, and (2.x only)
    ``stamped``, whether the topic's payloads lead with an injected timestamp. ``stamped is None`` is a
    1.x announcement (three strings); a bool is a 2.x one (a fourth, one-byte field)."""

    __slots__ = ("md5", "name", "definition", "stamped")

    def __init__(self, md5: str, name: str, definition: str, stamped: Optional[bool] = None) -> None:
        self.md5, self.name, self.definition, self.stamped = md5, name, definition, stamped

    @classmethod
    def of(cls, data_class: Type[genpy.Message], *, stamped: Optional[bool] = None) -> "RosMsgType":
        """The announcement for a genpy message class."""
        return cls(data_class._md5sum, data_class._type, data_class._full_text, stamped)

    @property
    def wire(self) -> WireGeneration:
        """The generation this announcement follows (and its topic's payloads)."""
        return WireGeneration.V1 if self.stamped is None else WireGeneration.V2

    def for_wire(self, wire: WireGeneration, *, stamped: bool) -> "RosMsgType":
        """The same type announced in ``wire``'s form (``stamped`` is kept only for 2.x)."""
        return RosMsgType(self.md5, self.name, self.definition, stamped if wire is WireGeneration.V2 else None)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RosMsgType) and (self.md5, self.name, self.definition, self.stamped) == (
            other.md5, other.name, other.definition, other.stamped)

    def __repr__(self) -> str:
        return (f"RosMsgType(md5={self.md5!r}, name={self.name!r}, definition=<{len(self.definition)} chars>, "
                f"stamped={self.stamped!r})")


def encode_msg_type(t: RosMsgType) -> bytes:
    """``RosMsgType`` in ROS 1 serialization: three length-prefixed UTF-8 strings, and for a 2.x
    announcement (``stamped`` not None) one byte 0 or 1."""
    out = bytearray()
    for s in (t.md5, t.name, t.definition):
        b = s.encode("utf-8")
        out += _LEN.pack(len(b)) + b
    if t.stamped is not None:
        out.append(1 if t.stamped else 0)
    return bytes(out)


def decode_msg_type(payload: bytes) -> RosMsgType:
    """Inverse of :func:`encode_msg_type`, either generation (told apart by what follows the three strings:
    nothing is 1.x, one byte 0/1 is 2.x); checks lengths and that the name looks like ``pkg/Type``."""
    fields = []
    pos = 0
    for what in ("md5", "name", "definition"):
        if pos + 4 > len(payload):
            raise CodecError(f"RosMsgType ends before its {what} field")
        (n,) = _LEN.unpack_from(payload, pos)
        pos += 4
        if pos + n > len(payload):
            raise CodecError(f"RosMsgType {what} field claims {n} bytes, only {len(payload) - pos} remain")
        try:
            fields.append(bytes(payload[pos:pos + n]).decode("utf-8"))
        except UnicodeDecodeError as exc:
            raise CodecError(f"RosMsgType {what} field is not UTF-8") from exc
        pos += n
    md5, name, definition = fields
    if name.count("/") != 1 or len(md5) != 32:
        raise CodecError(f"RosMsgType names type {name!r} with md5 {md5!r}: expected 'package/Type' and 32 hex digits")
    rest = len(payload) - pos
    stamped: Optional[bool] = None
    if rest == 1:
        if payload[pos] not in (0, 1):
            raise CodecError(f"RosMsgType's stamped field (mqtt_client 2.x) is {payload[pos]}, must be 0 or 1")
        stamped = payload[pos] == 1
    elif rest:
        raise CodecError(f"RosMsgType has {rest} bytes after its definition: mqtt_client 1.x ends there, 2.x adds "
                         "one (stamped)")
    return RosMsgType(md5, name, definition, stamped)


# ----------------------------------------------------------------------------- primitive text


def _float_text(value: float, bits: int) -> str:
    """Shortest text that reads back to the same float32/float64 value."""
    if bits == 64 or not math.isfinite(value):
        return repr(float(value))
    for digits in range(6, 10):
        text = f"{value:.{digits}g}"
        if struct.unpack("<f", struct.pack("<f", float(text)))[0] == struct.unpack("<f", struct.pack("<f", value))[0]:
            return text
    return repr(float(value))


def msg_to_text(msg: genpy.Message) -> str:
    """A message as mqtt_client's primitive text: the bare value for std_msgs primitives, else YAML."""
    kind = PRIMITIVE_TYPES.get(msg._type)
    if kind is None:
        return str(msg)
    value = msg.data
    if kind == "bool":
        return "true" if value else "false"
    if kind == "string":
        return str(value)
    if kind in FLOAT_TYPES:
        return _float_text(float(value), 32 if kind == "float32" else 64)
    return str(int(value))


def probe_primitive(text: str) -> genpy.Message:
    """mqtt_client's probing of incoming text: bool (``true``/``false`` in any case: the real client takes
    ``True`` as a Bool), then int (Int32), then float (Float32), then String."""
    from std_msgs.msg import Bool, Float32, Int32, String

    stripped = text.strip()
    lowered = stripped.lower()
    if lowered in ("true", "false"):
        return Bool(data=lowered == "true")
    try:
        as_int = int(stripped, 10)
    except ValueError:
        pass
    else:
        if -2**31 <= as_int < 2**31:
            return Int32(data=as_int)
    try:
        as_float = float(stripped)
    except ValueError:
        pass
    else:
        if stripped and (not math.isfinite(as_float) or abs(as_float) <= 3.4028234663852886e38):
            return Float32(data=as_float)
    return String(data=text)


def text_to_msg(text: str, data_class: Type[genpy.Message]) -> genpy.Message:
    """Text as a message of a fixed primitive type; :class:`CodecError` in words when it does not fit."""
    kind = PRIMITIVE_TYPES.get(data_class._type)
    if kind is None:
        raise CodecError(f"{data_class._type} is not a primitive type (primitive types: "
                         f"{', '.join(PRIMITIVE_TYPES)})")
    stripped = text.strip()
    value: Any
    if kind == "string":
        value = text
    elif kind == "bool":
        lowered = stripped.lower()
        if lowered in ("true", "1"):
            value = True
        elif lowered in ("false", "0"):
            value = False
        else:
            raise CodecError(f"text {_short(text)} is not a bool (true/false) for {data_class._type}")
    elif kind in FLOAT_TYPES:
        try:
            value = float(stripped)
        except ValueError:
            raise CodecError(f"text {_short(text)} is not a number for {data_class._type}") from None
    else:
        try:
            value = int(stripped, 10)
        except ValueError:
            raise CodecError(f"text {_short(text)} is not an integer for {data_class._type}") from None
        lo, hi = _INT_RANGES[kind]
        if not lo <= value <= hi:
            raise CodecError(f"{value} does not fit {data_class._type} ({lo}..{hi})")
    return data_class(data=value)


def _short(text: str) -> str:
    return repr(text if len(text) <= 40 else text[:40] + "...")


# ----------------------------------------------------------------------------- JSON


def _to_jsonable(value: Any) -> Any:
    if isinstance(value, genpy.Message):
        return {slot: _to_jsonable(getattr(value, slot)) for slot in value.__slots__}
    if isinstance(value, (genpy.Time, genpy.Duration)):
        return {"secs": int(value.secs), "nsecs": int(value.nsecs)}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [_to_jsonable(v) for v in value]
    if hasattr(value, "tolist") and getattr(value, "ndim", 1) <= 1:  # numpy (rospy.numpy_msg), array.array
        return _to_jsonable(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def msg_to_json(msg: genpy.Message) -> str:
    """Every field of a message as one JSON object."""
    return json.dumps(_to_jsonable(msg), separators=(",", ":"))


def json_to_msg(text: str, data_class: Type[genpy.Message]) -> genpy.Message:
    """A message from JSON (missing fields keep their defaults); :class:`CodecError` naming the field."""
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise CodecError(f"not JSON: {exc}") from None
    msg = data_class()
    _fill(msg, data, msg._type)
    try:
        msg._check_types()
    except Exception as exc:  # genpy raises SerializationError/TypeError/ValueError in words
        raise CodecError(f"JSON does not fit {data_class._type}: {exc}") from None
    return msg


def _fill(msg: genpy.Message, data: Any, where: str) -> None:
    if not isinstance(data, dict):
        raise CodecError(f"{where}: expected a JSON object, got {type(data).__name__}")
    types = dict(zip(msg.__slots__, msg._slot_types))
    for key, value in data.items():
        if key not in types:
            raise CodecError(f"{where}: {msg._type} has no field {key!r}")
        setattr(msg, key, _convert(getattr(msg, key), types[key], value, f"{where}.{key}"))


def _convert(current: Any, slot_type: str, value: Any, where: str) -> Any:
    slot = parse_slot_type(slot_type)
    base = slot.base
    if slot.is_array:
        if slot.is_bytes:
            if not isinstance(value, list) or not all(isinstance(v, int) and 0 <= v <= 255 for v in value):
                raise CodecError(f"{where}: expected a list of numbers 0..255")
            return bytes(value)
        if not isinstance(value, list):
            raise CodecError(f"{where}: expected a JSON array")
        if base in genmsg.msgs.BUILTIN_TYPES:
            return [_scalar(base, v, f"{where}[{i}]") for i, v in enumerate(value)]
        import roslib.message

        cls = roslib.message.get_message_class(genmsg.msgs.resolve_type(base, "std_msgs"))
        if cls is None:
            raise CodecError(f"{where}: unknown message type {base}")
        items = []
        for i, v in enumerate(value):
            item = cls()
            _fill(item, v, f"{where}[{i}]")
            items.append(item)
        return items
    if isinstance(current, genpy.Message):
        _fill(current, value, where)
        return current
    return _scalar(base, value, where)


def _scalar(base: str, value: Any, where: str) -> Any:
    if base in TIME_TYPES:
        if not isinstance(value, dict):
            raise CodecError(f"{where}: expected {{\"secs\": ..., \"nsecs\": ...}}")
        cls = genpy.Time if base == "time" else genpy.Duration
        return cls(int(value.get("secs", 0)), int(value.get("nsecs", 0)))
    if base in FLOAT_TYPES and isinstance(value, str):
        try:
            return float(value)                       # "nan", "inf" as written by msg_to_json
        except ValueError:
            raise CodecError(f"{where}: {value!r} is not a number") from None
    return value


# ----------------------------------------------------------------------------- RPC (AimRT's mqtt RPC back end)

#: AimRT's topic prefixes: requests on ``aimrt_rpc_req/<service>`` (servers share ``$share/aimrt/...``),
#: responses on ``aimrt_rpc_rsp/<client id>/<service>``; ``<service>`` URL-encoded.
RPC_REQUEST_PREFIX = "aimrt_rpc_req/"
RPC_RESPONSE_PREFIX = "aimrt_rpc_rsp/"
RPC_SHARE_GROUP = "$share/aimrt/"
_ID = struct.Struct("<I")          # AimRT writes its uint32s in host (little-endian) order
_STATUS = struct.Struct("<I")


def _short_field(data: bytes, pos: int, what: str) -> Tuple[str, int]:
    if pos >= len(data):
        raise CodecError(f"RPC packet ends before its {what}")
    n = data[pos]
    if pos + 1 + n > len(data):
        raise CodecError(f"RPC packet's {what} claims {n} bytes, only {len(data) - pos - 1} remain")
    try:
        return data[pos + 1:pos + 1 + n].decode("utf-8"), pos + 1 + n
    except UnicodeDecodeError:
        raise CodecError(f"RPC packet's {what} is not UTF-8") from None


def _counted(text: str, what: str) -> bytes:
    raw = text.encode("utf-8")
    if len(raw) > 255:
        raise CodecError(f"{what} {text[:40]!r}... is longer than 255 bytes")
    return bytes([len(raw)]) + raw


def encode_rpc_request(content_type: str, response_topic: str, msg_id: int, data: bytes) -> bytes:
    """AimRT's request: ``| n | content type | m | response topic | msg id (4) | data |``."""
    return (_counted(content_type, "content type") + _counted(response_topic, "response topic") + _ID.pack(msg_id)
            + data)


def decode_rpc_request(payload: bytes) -> Tuple[str, str, int, bytes]:
    """(content type, response topic, msg id, data) of a request."""
    content_type, pos = _short_field(payload, 0, "content type")
    response_topic, pos = _short_field(payload, pos, "response topic")
    if pos + 4 > len(payload):
        raise CodecError("RPC request ends before its 4-byte msg id")
    return content_type, response_topic, _ID.unpack_from(payload, pos)[0], payload[pos + 4:]


def encode_rpc_response(content_type: str, msg_id: int, status: int, data: bytes) -> bytes:
    """AimRT's response: ``| n | content type | msg id (4) | status code (4) | data |``."""
    return _counted(content_type, "content type") + _ID.pack(msg_id) + _STATUS.pack(status) + data


def decode_rpc_response(payload: bytes) -> Tuple[str, int, int, bytes]:
    """(content type, msg id, status code, data) of a response."""
    content_type, pos = _short_field(payload, 0, "content type")
    if pos + 8 > len(payload):
        raise CodecError("RPC response ends before its msg id and status code")
    msg_id, status = _ID.unpack_from(payload, pos)[0], _STATUS.unpack_from(payload, pos + 4)[0]
    return content_type, msg_id, status, payload[pos + 8:]

