"""The microcontroller link's wire format (seed 003, the CVRA ROS MessagePack bridge): pure functions.

CVRA's cvra_rpc (cvra/robot-software) went through three forms; the link **reads every one of them** from
every board and **writes the one its configuration names** (:class:`WireForm`, the ``wire_form`` key)::

    final   (babf2cfa, 2018..2019; the default)  msgpack([name, args])
            args: nil (no fields), the one field's value bare (one field), or [field1, field2, ...]
    mid2015 (feb95469)                            msgpack([name, field1, field2, ...])
    readme  (0670b782, the seed README)           msgpack(name) + msgpack({field: value, ...})   (two objects)
    map     (micros_rt before issue 37)           msgpack([name, {field: value, ...}])

A topic datagram is one of these; a service request is one of these as a *serial datagram* -- the payload,
its CRC32 (zlib's, big-endian) appended, SLIP-escaped (END 0xC0 -> ESC 0xDB + 0xDC, ESC -> ESC + 0xDD) and
closed by END. What follows the name (:func:`split_datagram`, :func:`decode_request`) is read by
:meth:`MessageCodec.from_args`: nothing or nil is no fields; one map is the fields by name; one array is the
fields in definition order; several values are the fields in order; one other value is the value of a type's
only field. The server answers one MessagePack object, unframed, and closes the connection: CVRA's handlers
answer bare values (``"pong"``, ``true``) or nil; :meth:`MessageCodec.from_answer` maps each onto the ROS
response. A connection closed without any answer is an error for every response type.

Nested messages are nested maps in the readme and map forms and arrays in definition order in the final and
mid2015 forms (CVRA's handlers index positional arguments); either is read. ``time``/``duration`` are
``[secs, nsecs]``, ``uint8[]``/``char[]`` are MessagePack bin.

Every ROS message type works: codecs are built from genpy's ``__slots__``/``_slot_types``.

>>> from std_msgs.msg import String
>>> encode_datagram("chatter", MessageCodec(String).to_wire(String(data="hi")))
b'\\x92\\xa7chatter\\xa2hi'
>>> encode_datagram("chatter", {"data": "hi"}, form=WireForm.README)
b'\\xa7chatter\\x81\\xa4data\\xa2hi'
"""

from __future__ import annotations

import enum
import struct
import threading
import zlib
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple, Type

import genpy
import msgpack
import roslib.message

from micros_rt.rostypes import FLOAT_TYPES, INT_RANGES, TIME_TYPES, parse_slot_type

from .errors import WireError

__all__ = [
    "WireForm", "WIRE_FORM_NAMES", "Float32", "pack", "Answer", "to_args", "END", "ESC", "ESC_END", "ESC_ESC", "MessageCodec", "codec_for", "encode_datagram", "split_datagram",
    "frame", "unframe", "FrameReader", "encode_request", "decode_request", "encode_response",
    "decode_response", "Payload", "split_payload", "decode_request_payload", "DEFAULT_WIRE_FORM",
]

END = 0xC0
ESC = 0xDB
ESC_END = 0xDC
ESC_ESC = 0xDD

_INT_RANGES: Dict[str, Tuple[int, int]] = INT_RANGES  # the one table (micros_rt.rostypes)
_FLOATS = FLOAT_TYPES
_NSEC = 1_000_000_000


class WireForm(enum.Enum):
    """What the link writes to a board (it reads every form whatever this is): the ``wire_form`` config key.

    Each is what one era of CVRA's cvra/robot-software writes and reads (the commit is the one whose code the
    fixtures in tests/fixtures/cvra/ were captured from).
    """

    #: CVRA's final cvra_rpc (babf2cfa; unchanged until a5061d96): ``[name, args]``, args nil (no fields), the
    #: only field's value bare, or ``[field1, ...]``; nested messages as arrays. Answers the same way.
    FINAL = "final"
    #: The name this form had before: ``wire_form: cvra`` means the final form.
    CVRA = "final"
    #: CVRA's cvra_rpc of mid-2015 (feb95469): ``[name, field1, field2, ...]``; nested messages as arrays.
    MID2015 = "mid2015"
    #: The seed README's (and 0670b782's service calls): ``name`` then ``{fields}``, two MessagePack objects.
    README = "readme"
    #: ``[name, {fields}]``: what micros_rt wrote as ``cvra`` before issue 37 (answers as a map of fields).
    MAP = "map"


#: What the link writes to a board that has sent nothing yet (no ``wire_form`` set): CVRA's final form.
DEFAULT_WIRE_FORM = WireForm.FINAL

#: ``wire_form`` values a configuration may use, with what each means (the error message lists them).
WIRE_FORM_NAMES: Dict[str, WireForm] = {
    "final": WireForm.FINAL, "cvra": WireForm.FINAL, "babf2cfa": WireForm.FINAL,
    "mid2015": WireForm.MID2015, "feb95469": WireForm.MID2015,
    "readme": WireForm.README, "0670b782": WireForm.README,
    "map": WireForm.MAP,
}


class Float32(float):
    """A float32 field's value: :func:`pack` writes it as MessagePack float32 (0xCA), as the field's type is."""

    __slots__ = ()


def pack(obj: Any) -> bytes:
    """``msgpack.packb(obj, use_bin_type=True)``, except that :class:`Float32` values are packed as float32.

    >>> pack({"data": Float32(1.5)}).hex()
    '81a464617461ca3fc00000'
    """
    if not _has_float32(obj):
        packed: bytes = msgpack.packb(obj, use_bin_type=True)
        return packed
    out = bytearray()
    _pack_into(out, obj, msgpack.Packer(use_bin_type=True))
    return bytes(out)


def _has_float32(obj: Any) -> bool:
    if isinstance(obj, Float32):
        return True
    if isinstance(obj, dict):
        return any(_has_float32(v) for v in obj.values())
    if isinstance(obj, list):
        return any(_has_float32(v) for v in obj)
    return False


def _pack_into(out: bytearray, obj: Any, packer: msgpack.Packer) -> None:
    if isinstance(obj, Float32):
        out += b"\xca" + struct.pack(">f", obj)
    elif isinstance(obj, dict):
        out += packer.pack_map_header(len(obj))
        for k, v in obj.items():
            _pack_into(out, k, packer)
            _pack_into(out, v, packer)
    elif isinstance(obj, list):
        out += packer.pack_array_header(len(obj))
        for v in obj:
            _pack_into(out, v, packer)
    else:
        out += packer.pack(obj)

# Encoder and decoder of one field: to_wire(value, path) and from_wire(obj, path).
_Enc = Callable[[Any, str], Any]
_Dec = Callable[[Any, str], Any]


def _shown(obj: Any) -> str:
    """A received value in words, short enough for a log line."""
    kinds = {bool: "a boolean", int: "an integer", float: "a float", str: "the string",
             bytes: "bin data", list: "an array", dict: "a map", type(None): "nil"}
    kind = kinds.get(type(obj), type(obj).__name__)
    if obj is None:
        return kind
    if isinstance(obj, (bool, int, float, str)):
        text = repr(obj)
        return f"{kind} {text[:40]}{'...' if len(text) > 40 else ''}"
    if isinstance(obj, (bytes, list, dict)):
        return f"{kind} of {len(obj)}"
    return kind


def _bad(path: str, expected: str, obj: Any) -> WireError:
    return WireError("bad_field", f"field '{path}' should be {expected}, got {_shown(obj)}")


def _message_class(type_name: str) -> Type[genpy.Message]:
    if type_name == "Header":
        type_name = "std_msgs/Header"
    cls = roslib.message.get_message_class(type_name)
    if cls is None:
        raise ValueError(f"unknown ROS message type {type_name!r}")
    return cls  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- scalar codecs

def _int_codec(base: str) -> Tuple[_Enc, _Dec]:
    lo, hi = _INT_RANGES[base]
    expected = f"an integer {base} ({lo}..{hi})"

    def enc(v: Any, path: str) -> Any:
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise genpy.SerializationError(f"field '{path}': {v!r} is not {expected}")
        return v

    def dec(obj: Any, path: str) -> Any:
        if isinstance(obj, bool) or not isinstance(obj, int) or not lo <= obj <= hi:
            raise _bad(path, expected, obj)
        return obj
    return enc, dec


def _float_codec(base: str) -> Tuple[_Enc, _Dec]:
    def enc(v: Any, path: str) -> Any:
        if hasattr(v, "dtype") and hasattr(v, "item"):  # numpy scalars (numpy_msg arrays' elements)
            v = v.item()
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise genpy.SerializationError(f"field '{path}': {v!r} is not a number ({base})")
        if base == "float64":
            return float(v)
        try:
            struct.pack(">f", v)
        except OverflowError:
            raise genpy.SerializationError(f"field '{path}': {v!r} is out of float32's range") from None
        return Float32(v)

    def dec(obj: Any, path: str) -> Any:
        if isinstance(obj, bool) or not isinstance(obj, (int, float)):
            raise _bad(path, f"a number ({base})", obj)
        return float(obj)
    return enc, dec


def _bool_enc(v: Any, path: str) -> Any:
    if not isinstance(v, (bool, int)):
        raise genpy.SerializationError(f"field '{path}': {v!r} is not a bool")
    return bool(v)


def _bool_dec(obj: Any, path: str) -> Any:
    if isinstance(obj, bool):
        return obj
    if isinstance(obj, int) and obj in (0, 1):  # C firmware often sends 0/1
        return bool(obj)
    raise _bad(path, "a boolean (true/false, or 0/1)", obj)


def _string_enc(v: Any, path: str) -> Any:
    if isinstance(v, bytes):
        try:
            return v.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise genpy.SerializationError(f"field '{path}': not UTF-8 text: {exc}") from exc
    if not isinstance(v, str):
        raise genpy.SerializationError(f"field '{path}': {v!r} is not a string")
    return v


def _string_dec(obj: Any, path: str) -> Any:
    if not isinstance(obj, str):
        raise _bad(path, "a string", obj)
    return obj


def _time_codec(base: str) -> Tuple[_Enc, _Dec]:
    cls = genpy.Time if base == "time" else genpy.Duration
    lo, hi = _INT_RANGES["uint32" if base == "time" else "int32"]
    expected = f"[secs, nsecs] ({base}: secs {lo}..{hi}, nsecs 0..999999999)"

    def enc(v: Any, path: str) -> Any:
        if not isinstance(v, (genpy.Time, genpy.Duration)):
            raise genpy.SerializationError(f"field '{path}': {v!r} is not a {base}")
        return [v.secs, v.nsecs]

    def dec(obj: Any, path: str) -> Any:
        if (not isinstance(obj, list) or len(obj) != 2
                or any(isinstance(x, bool) or not isinstance(x, int) for x in obj)
                or not lo <= obj[0] <= hi or not 0 <= obj[1] < _NSEC):
            raise _bad(path, expected, obj)
        return cls(obj[0], obj[1])
    return enc, dec


def _bytes_codec(size: Optional[int]) -> Tuple[_Enc, _Dec]:
    expected = "bin data" + (f" of exactly {size} bytes" if size is not None else "")

    def enc(v: Any, path: str) -> Any:
        try:
            data = bytes(v)
        except (TypeError, ValueError) as exc:
            raise genpy.SerializationError(f"field '{path}': {v!r} is not bytes: {exc}") from exc
        if size is not None and len(data) != size:
            raise genpy.SerializationError(f"field '{path}': {len(data)} bytes, the type needs {size}")
        return data

    def dec(obj: Any, path: str) -> Any:
        if isinstance(obj, list) and all(isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= 255
                                         for x in obj):
            obj = bytes(obj)  # an array of small integers is accepted for uint8[] too
        if not isinstance(obj, bytes) or (size is not None and len(obj) != size):
            raise _bad(path, expected, obj)
        return obj
    return enc, dec


def _array_codec(item: Tuple[_Enc, _Dec], size: Optional[int]) -> Tuple[_Enc, _Dec]:
    item_enc, item_dec = item
    expected = "an array" + (f" of exactly {size} elements" if size is not None else "")

    def enc(v: Any, path: str) -> Any:
        if hasattr(v, "tolist") and getattr(v, "ndim", 1) == 1:  # numpy arrays (rospy.numpy_msg), array.array
            v = v.tolist()
        if not isinstance(v, (list, tuple)):
            raise genpy.SerializationError(f"field '{path}': {v!r} is not a list")
        if size is not None and len(v) != size:
            raise genpy.SerializationError(f"field '{path}': {len(v)} elements, the type needs {size}")
        return [item_enc(x, f"{path}[{i}]") for i, x in enumerate(v)]

    def dec(obj: Any, path: str) -> Any:
        if not isinstance(obj, list) or (size is not None and len(obj) != size):
            raise _bad(path, expected, obj)
        return [item_dec(x, f"{path}[{i}]") for i, x in enumerate(obj)]
    return enc, dec


def _field_codec(slot_type: str) -> Tuple[_Enc, _Dec]:
    slot = parse_slot_type(slot_type)
    if slot.is_bytes:
        return _bytes_codec(slot.length)
    base = slot.base
    if base in _INT_RANGES:
        one = _int_codec(base)
    elif base in _FLOATS:
        one = _float_codec(base)
    elif base == "bool":
        one = (_bool_enc, _bool_dec)
    elif base == "string":
        one = (_string_enc, _string_dec)
    elif base in TIME_TYPES:
        one = _time_codec(base)
    else:
        nested = codec_for(_message_class(base))
        one = (nested._enc, nested._dec)
    return _array_codec(one, slot.length) if slot.is_array else one


# --------------------------------------------------------------------------- messages

class MessageCodec:
    """Converts one ROS message type to and from its MessagePack form (maps of fields).

    ``to_wire`` raises ``genpy.SerializationError`` on a bad field value (like genpy's serializer);
    ``from_wire`` raises :class:`WireError` (``missing_field``, ``unknown_field``, ``bad_field``) naming
    the field path. Use :func:`codec_for` to share one codec per type.
    """

    def __init__(self, data_class: Type[genpy.Message]) -> None:
        self.data_class = data_class
        self.type_name: str = data_class._type
        self.field_names: Tuple[str, ...] = tuple(data_class.__slots__)
        self._codecs: List[Tuple[str, _Enc, _Dec]] = [
            (name, *_field_codec(slot)) for name, slot in zip(data_class.__slots__, data_class._slot_types)]

    def to_wire(self, msg: genpy.Message) -> Dict[str, Any]:
        """The fields of ``msg`` as a dict ready for ``msgpack.packb`` (definition order)."""
        return self._enc(msg, "")  # type: ignore[no-any-return]

    def to_wire_list(self, msg: genpy.Message) -> List[Any]:
        """The fields of ``msg`` as a list in definition order (nested messages stay maps)."""
        return list(self.to_wire(msg).values())

    def from_wire(self, obj: Any) -> genpy.Message:
        """A message from a map of fields or an array of them in definition order."""
        return self._dec(obj, "")

    @property
    def field_count(self) -> int:
        return len(self._codecs)

    def from_args(self, rest: List[Any]) -> genpy.Message:
        """A message from what follows its name in a datagram or request (:func:`split_datagram`,
        :func:`decode_request`), in any era's form:

        - ``[]`` or ``[nil]``: no fields (CVRA's ``encode(name)``; mid-2015's ``[name]``);
        - ``[{fields}]``: the fields by name (the README's and micros_rt's map form);
        - ``[[f1, f2, ...]]``: the fields in definition order (CVRA's final list arguments);
        - ``[f1, f2, ...]`` (two or more): the fields in definition order (CVRA's mid-2015 form);
        - ``[value]``: the value of the type's only field (CVRA's final bare argument, mid-2015's one field).

        For a type with one field, ``[x]`` with ``x`` a map or an array is ambiguous (the fields, or the only
        field's value): the fields are tried first, the bare value if that fails, and the first error is
        reported if neither reads.

        >>> from geometry_msgs.msg import Pose2D
        >>> codec_for(Pose2D).from_args([[1.5, 2.5, 0.5]]).theta
        0.5
        >>> codec_for(roslib.message.get_service_class("std_srvs/SetBool")._request_class).from_args([True])
        data: True
        """
        if not rest or (len(rest) == 1 and rest[0] is None):
            return self._dec({}, "")
        if len(rest) > 1:
            return self._dec(rest, "")
        args = rest[0]
        if isinstance(args, (dict, list)):
            try:
                return self._dec(args, "")
            except WireError as as_fields:
                if len(self._codecs) != 1:
                    raise
                try:
                    return self._dec([args], "")
                except WireError:
                    raise as_fields from None
        if len(self._codecs) != 1:
            raise WireError("bad_shape", f"one bare value ({_shown(args)}) can only stand for a type with one "
                                         f"field; {self.type_name} has {len(self._codecs)}"
                            + (f" ({', '.join(self.field_names)}): send them as an array in this order or a map"
                               if self._codecs else ": send nil or nothing"))
        return self._dec([args], "")

    def from_request(self, rest: List[Any]) -> genpy.Message:
        """A service request from what follows its name (:func:`decode_request`): :meth:`from_args`."""
        return self.from_args(rest)

    def from_answer(self, answer: Any) -> "Answer":
        """A service response from a board's answer (:func:`decode_response`), in any era's form.

        A map is the fields by name, an array the fields in definition order, and for a response type with
        one field, any other value is that field's. CVRA's handlers answer bare values or nil, mapped thus:

        - ``nil``: an empty response type (``std_srvs/Empty``, ``roscpp/SetLoggerLevel``) is answered. A type
          with a ``success`` bool (``std_srvs/Trigger``, ``SetBool``) gets ``success: false`` and a message
          saying the board answered nil: CVRA's C firmware answers nil both when a handler wrote nothing and
          when it has no handler of that name, so nil is no evidence of success. Any other type: an error.
        - ``true``/``false``: a ``success`` bool field gets it (the message stays empty); an empty response
          type accepts ``true`` and is an error for ``false``.
        - a string: a type with ``success`` and ``message`` gets ``success: true`` and the string as its
          message (CVRA's ``ping`` answers ``"pong"``); an empty type accepts it and the text is reported in
          :attr:`Answer.note` (CVRA's ``config_update`` answers its errors as text).

        Anything else that does not fit raises :class:`WireError` naming the response type and its fields.

        >>> from std_srvs.srv import Trigger
        >>> codec_for(Trigger._response_class).from_answer("pong").response
        success: True
        message: "pong"
        """
        fields = dict(zip(self.field_names, (slot for slot in self.data_class._slot_types)))
        has_success = fields.get("success") == "bool"
        has_message = fields.get("message") == "string"
        if isinstance(answer, (dict, list)):
            try:
                return Answer(self._dec(answer, ""))
            except WireError as as_fields:
                if len(self._codecs) != 1:
                    raise
                try:
                    return Answer(self._dec([answer], ""))
                except WireError:
                    raise as_fields from None
        if len(self._codecs) == 1 and answer is not None:
            try:
                return Answer(self._dec([answer], ""))
            except WireError:
                if not has_success:
                    raise
        if not self._codecs:
            if answer is None or answer is True:
                return Answer(self.data_class())
            if answer is False:
                raise WireError("bad_field", f"the board answered false: the call failed ({self.type_name} has no "
                                             f"field to carry more)")
            return Answer(self.data_class(), f"the board answered {_shown(answer)}, which {self.type_name} has no "
                                             f"field for; the call is taken as answered")
        if has_success:
            msg = self.data_class()
            if answer is None:
                msg.success = False
                if has_message:
                    msg.message = ("the board answered nil (no result): CVRA's firmware answers nil when its handler "
                                   "wrote nothing and also when it has no handler of that name, so this is not "
                                   "reported as a success")
                return Answer(msg, "the board answered nil; success is false")
            if isinstance(answer, bool):
                msg.success = answer
                return Answer(msg)
            if isinstance(answer, str) and has_message:
                msg.success = True
                msg.message = answer
                return Answer(msg)
        raise WireError("bad_shape", f"the answer {_shown(answer)} cannot fill a {self.type_name}, whose fields are "
                                     f"{', '.join(self.field_names)}: the board should answer a map of them, an array "
                                     f"of them in this order" + (", or one value for the only field"
                                                                 if len(self._codecs) == 1 else ""))

    def _enc(self, msg: Any, path: str) -> Any:
        if not isinstance(msg, self.data_class):
            raise genpy.SerializationError(
                f"field '{path or '.'}': expected a {self.type_name} message, got {type(msg).__name__}")
        prefix = f"{path}." if path else ""
        return {name: enc(getattr(msg, name), prefix + name) for name, enc, _ in self._codecs}

    def _dec(self, obj: Any, path: str) -> Any:
        prefix = f"{path}." if path else ""
        msg = self.data_class()
        if isinstance(obj, dict):
            unknown = [k for k in obj if k not in self.field_names]
            if unknown:
                raise WireError("unknown_field",
                                f"{self.type_name} has no field {_shown(unknown[0])} (at '{path or '.'}'); "
                                f"its fields are {', '.join(self.field_names)}")
            for name, _, dec in self._codecs:
                if name not in obj:
                    raise WireError("missing_field", f"field '{prefix}{name}' ({self.type_name}) is missing")
                setattr(msg, name, dec(obj[name], prefix + name))
            return msg
        if isinstance(obj, list):
            if len(obj) != len(self._codecs):
                kind = "missing_field" if len(obj) < len(self._codecs) else "unknown_field"
                raise WireError(kind, f"'{path or '.'}': {self.type_name} in array form needs "
                                      f"{len(self._codecs)} fields ({', '.join(self.field_names)}), got {len(obj)}")
            for (name, _, dec), value in zip(self._codecs, obj):
                setattr(msg, name, dec(value, prefix + name))
            return msg
        raise _bad(path or ".", f"a {self.type_name} as a map of fields (or an array in definition order)", obj)


class Answer:
    """A board's answer read as a ROS response (:meth:`MessageCodec.from_answer`): ``response``, and ``note``
    when part of the answer had no field to go to (the bridge logs it)."""

    __slots__ = ("response", "note")

    def __init__(self, response: genpy.Message, note: Optional[str] = None) -> None:
        self.response = response
        self.note = note


def _as_arrays(value: Any) -> Any:
    """A to_wire value with every nested message (a dict) turned into an array in definition order."""
    if isinstance(value, dict):
        return [_as_arrays(v) for v in value.values()]
    if isinstance(value, list):
        return [_as_arrays(v) for v in value]
    return value


def to_args(fields: Dict[str, Any]) -> Any:
    """The arguments CVRA's final form carries for ``fields`` (:meth:`MessageCodec.to_wire`'s map): nil when
    there are none, the only field's value bare, else an array in definition order; nested messages as arrays.

    >>> to_args({}), to_args({"data": True}), to_args({"x": 1.5, "y": 2.5, "theta": 0.5})
    (None, True, [1.5, 2.5, 0.5])
    """
    values = [_as_arrays(v) for v in fields.values()]
    if not values:
        return None
    return values[0] if len(values) == 1 else values


_codecs: Dict[Type[genpy.Message], MessageCodec] = {}
_codecs_lock = threading.RLock()


def codec_for(data_class: Type[genpy.Message]) -> MessageCodec:
    """The (shared) codec of ``data_class``; nested types get theirs on first use."""
    with _codecs_lock:
        codec = _codecs.get(data_class)
        if codec is None:
            codec = _codecs[data_class] = MessageCodec(data_class)
        return codec


# --------------------------------------------------------------------------- topic datagrams

def _call(name: str, fields: Dict[str, Any], form: WireForm) -> bytes:
    """``name`` and ``fields`` (a to_wire map) in ``form``: the payload of a datagram or of a request."""
    if form is WireForm.README:
        return pack(name) + pack(fields)
    if form is WireForm.MAP:
        return pack([name, fields])
    if form is WireForm.MID2015:
        return pack([name, *(_as_arrays(v) for v in fields.values())])
    return pack([name, to_args(fields)])


def encode_datagram(name: str, fields: Dict[str, Any], *, form: WireForm = WireForm.FINAL) -> bytes:
    """One topic datagram of ``fields`` (:meth:`MessageCodec.to_wire`'s map) in ``form`` (see the module).

    >>> encode_datagram("odometry_raw", {"x": Float32(1.5), "y": Float32(2.5), "theta": Float32(0.5)}).hex(" ")
    '92 ac 6f 64 6f 6d 65 74 72 79 5f 72 61 77 93 ca 3f c0 00 00 ca 40 20 00 00 ca 3f 00 00 00'
    """
    return _call(name, fields, form)


def _unpack_all(data: bytes, at_most: int) -> List[Any]:
    """Up to ``at_most`` MessagePack objects making up ``data`` entirely (else WireError)."""
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False, max_buffer_size=max(len(data), 1))
    unpacker.feed(data)
    objects: List[Any] = []
    try:
        for obj in unpacker:
            objects.append(obj)
            if len(objects) > at_most:
                raise WireError("bad_shape", f"more than {at_most} MessagePack objects in one datagram")
    except WireError:
        raise
    except (ValueError, TypeError, msgpack.UnpackException) as exc:  # FormatError, StackError, bad UTF-8,
        # an array or map used as a map key (unhashable), ...
        raise WireError("not_msgpack", f"not MessagePack ({str(exc) or type(exc).__name__}; the datagram starts "
                                       f"{data[:8].hex(' ')})") from exc
    if unpacker.tell() != len(data):
        raise WireError("not_msgpack", f"not MessagePack (truncated after byte {unpacker.tell()} of {len(data)})")
    if not objects:
        raise WireError("not_msgpack", "an empty datagram")
    return objects


class Payload(NamedTuple):
    """A datagram or request split into its name and what follows it (undecoded), and how it was laid out:
    ``separate`` when the name and the arguments were two MessagePack objects (the README's form)."""

    name: str
    rest: List[Any]
    separate: bool

    def form(self, field_count: int) -> Optional[WireForm]:
        """The CVRA era only one of whose forms lays out these arguments for a type of ``field_count``
        fields, or None when several eras write the same bytes (a one-field type's ``[name, value]`` is the
        final and the mid-2015 form alike).

        >>> split_payload(bytes.fromhex("91a3666f6f")).form(0).value        # mid-2015 encode("foo")
        'mid2015'
        >>> split_payload(bytes.fromhex("92a3666f6fc0")).form(0).value      # final encode("foo")
        'final'
        >>> split_payload(bytes.fromhex("92a57370656564ca3fc00000")).form(1) is None   # [speed, 1.5]
        True
        """
        if self.separate:
            return WireForm.README
        if len(self.rest) != 1:
            return WireForm.MID2015   # [name] (no arguments) or [name, f1, f2, ...]: only mid-2015 writes these
        if self.rest[0] is None:
            return WireForm.FINAL     # [name, nil]: the final form's "no arguments" (mid-2015 writes [name])
        if field_count != 1:
            return WireForm.FINAL     # [name, [f1, ...]] or [name, {..}]: one argument object for several fields
        return None


def _split(objects: List[Any], what: str) -> Payload:
    first = objects[0]
    if len(objects) == 2 and isinstance(first, str):
        return Payload(first, [objects[1]], True)   # the README's name then {fields} (or any one object)
    if len(objects) == 1 and isinstance(first, list) and first and isinstance(first[0], str):
        return Payload(first[0], first[1:], False)  # [name, args] (final), [name, *fields] (mid-2015), [name, {..}]
    raise WireError("bad_shape", f"{what} must be an array [name, args...] or a name (string) followed by its "
                                 f"arguments; got {' + '.join(_shown(o) for o in objects)}")


def split_datagram(data: bytes) -> Tuple[str, List[Any]]:
    """The stream name and what follows it, undecoded (read it with :meth:`MessageCodec.from_args`).

    >>> split_datagram(bytes.fromhex("a3696d7581a17801"))
    ('imu', [{'x': 1}])
    >>> split_datagram(bytes.fromhex("92a3696d7581a17801"))
    ('imu', [{'x': 1}])
    >>> split_datagram(bytes.fromhex("93a3696d750102"))
    ('imu', [1, 2])
    """
    name, rest, _ = split_payload(data)
    return name, rest


def split_payload(data: bytes) -> Payload:
    """A topic datagram's name, what follows it (undecoded) and its layout (:meth:`Payload.form`)."""
    return _split(_unpack_all(data, 2), "a topic datagram")


# --------------------------------------------------------------------------- serial datagrams (SLIP + CRC32)

_ESCAPES = {END: bytes((ESC, ESC_END)), ESC: bytes((ESC, ESC_ESC))}


def frame(payload: bytes) -> bytes:
    """A serial datagram: ``payload`` + CRC32 (big-endian), SLIP-escaped, then END.

    >>> frame(b"\\xc0").hex()
    'dbdc49662d3dc0'
    """
    data = payload + struct.pack(">I", zlib.crc32(payload) & 0xFFFFFFFF)
    return data.replace(bytes((ESC,)), _ESCAPES[ESC]).replace(bytes((END,)), _ESCAPES[END]) + bytes((END,))


def unframe(body: bytes) -> bytes:
    """The payload of one serial datagram (``body`` without its END); WireError on a bad escape or CRC."""
    out = bytearray()
    escaped = False
    for b in body:
        if escaped:
            if b == ESC_END:
                out.append(END)
            elif b == ESC_ESC:
                out.append(ESC)
            else:
                raise WireError("bad_escape", f"SLIP escape 0xDB followed by 0x{b:02X} (only 0xDC or 0xDD may follow)")
            escaped = False
        elif b == ESC:
            escaped = True
        else:
            out.append(b)
    if escaped:
        raise WireError("bad_escape", "the frame ends inside a SLIP escape (0xDB before END)")
    if len(out) < 4:
        raise WireError("short_frame", f"a frame of {len(out)} bytes cannot hold its 4-byte CRC32")
    payload, (crc,) = bytes(out[:-4]), struct.unpack(">I", out[-4:])
    actual = zlib.crc32(payload) & 0xFFFFFFFF
    if crc != actual:
        raise WireError("bad_crc", f"CRC32 mismatch: the frame says 0x{crc:08X}, the payload's is 0x{actual:08X}")
    return payload


class FrameReader:
    """Collects bytes until the first END; ``feed`` returns the frame's body (before END) once complete.

    Leading END bytes (an empty frame, sent by some firmware to flush the line) are skipped. More than
    ``max_size`` bytes without END is :class:`WireError` ``frame_too_long``.
    """

    def __init__(self, max_size: int) -> None:
        self.max_size = max_size
        self._buf = bytearray()

    def feed(self, data: bytes) -> Optional[bytes]:
        if not self._buf:
            data = data.lstrip(bytes((END,)))
        end = data.find(END)
        if end < 0:
            self._buf += data
            if len(self._buf) > self.max_size:
                raise WireError("frame_too_long", f"more than {self.max_size:,} bytes without a SLIP END (0xC0)")
            return None
        self._buf += data[:end]
        if len(self._buf) > self.max_size:
            raise WireError("frame_too_long", f"a frame of {len(self._buf):,} bytes, more than {self.max_size:,}")
        return bytes(self._buf)

    @property
    def pending(self) -> int:
        """Bytes received so far without END."""
        return len(self._buf)


# --------------------------------------------------------------------------- service calls

def encode_request(name: str, fields: Dict[str, Any], *, form: WireForm = WireForm.FINAL) -> bytes:
    """A service request as sent on the wire: the serial datagram of ``name`` and ``fields`` in ``form``.

    >>> encode_request("reset", {}).hex()
    '92a57265736574dbdced8dbc20c0'
    >>> encode_request("set_mode", {"data": True}, form=WireForm.README).hex(" ")
    'a8 73 65 74 5f 6d 6f 64 65 81 a4 64 61 74 61 c3 b3 08 db dc ed c0'
    """
    return frame(_call(name, fields, form))


def decode_request(body: bytes) -> Tuple[str, List[Any]]:
    """``(name, rest)`` from a received frame body (before END): ``rest`` is what follows the name, undecoded,
    in any era's form (:meth:`MessageCodec.from_args` reads it)."""
    name, rest, _ = decode_request_payload(body)
    return name, rest


def decode_request_payload(body: bytes) -> Payload:
    """A received request (frame body before END): its name, what follows (undecoded) and its layout."""
    return _split(_unpack_all(unframe(body), 2), "a service request")


def encode_response(fields: Dict[str, Any], *, form: WireForm = WireForm.FINAL) -> bytes:
    """A service answer (not framed): in the map form the response's fields as a map, in every other form
    as CVRA's handlers answer -- nil (no fields), the only field's value, or an array in definition order."""
    return pack(fields) if form is WireForm.MAP else pack(to_args(fields))


def decode_response(data: bytes) -> Any:
    """The undecoded answer: one MessagePack object (:meth:`MessageCodec.from_answer` reads it). No bytes at
    all is not an answer: :class:`WireError` ``no_answer``."""
    if not data:
        raise WireError("no_answer", "the connection was closed without an answer")
    return _unpack_all(data, 1)[0]
