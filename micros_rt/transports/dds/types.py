"""ROS 1 message classes as DDS types, with a generated CDR codec.

One rule for every genpy message class (docs/ros2.md, type mapping rules), chosen so ROS 2
nodes read micros_rt topics natively:

* DDS type name ``<pkg>::msg::dds_::<Type>_``; fields in order, names lower-cased
  where ROS 2 renamed them (sensor_msgs/CameraInfo ``D K R P`` -> ``d k r p``);
* ROS 1 ``time``/``duration`` -> ``builtin_interfaces`` Time/Duration (int32 sec,
  uint32 nanosec); ``std_msgs/Header`` -> ROS 2 Header (no ``seq``);
* ``uint8[]``/``char[]`` -> sequence<octet>, moved as ``bytes``.

Why a codec of our own instead of cyclonedds' IdlStruct objects: the binding's
per-sample object churn is the bottleneck, and going genpy -> IdlStruct
-> CDR would pay it twice. The codec writes XCDR1 (plain CDR, little endian, the
encoding ROS 2 uses) straight from the genpy message and reads straight back into
one. The IdlStruct class is still built, with the identical layout, because
Cyclone needs it to create the Topic and announce the type in discovery. Unit
tests check the codec byte for byte against cyclonedds' own serializer.
"""

from __future__ import annotations

import array
import numbers
import struct
import sys
import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple, Type

import genpy
import roslib.message

from ...cyclone import import_cyclonedds
from ...rostypes import BYTES_TYPES, FLOAT_TYPES, INT_RANGES, TIME_TYPES, parse_slot_type
from ...exceptions import MicrosRtError, TypeMappingError
from .typecache import type_key

try:  # genpy imports it too when it is installed; rospy.numpy_msg needs it
    import numpy
except ImportError:  # pragma: no cover - python3-numpy is a dependency (scripts/setup.sh)
    numpy = None  # type: ignore[assignment]

__all__ = ["DDSType", "MalformedSampleError", "dds_type_for", "dds_topic_name", "dds_type_name",
           "register_message_classes"]


class MalformedSampleError(MicrosRtError, ValueError):
    """A received DDS sample is not a valid CDR encoding of the expected type (truncated, lengths that
    do not fit, invalid UTF-8, ...). The message names the type and what is wrong."""

# ROS 1 primitive -> (struct code, size, ROS 2 idl type name)
_PRIMS: Dict[str, Tuple[str, int, str]] = {
    "bool": ("B", 1, "bool"),
    "int8": ("b", 1, "int8"),
    "uint8": ("B", 1, "uint8"),
    "byte": ("b", 1, "byte"),   # ROS 1 byte is int8; ROS 2 byte is octet: same bits
    "char": ("B", 1, "uint8"),  # ROS 1 char is uint8, as ROS 2 maps char
    "int16": ("h", 2, "int16"),
    "uint16": ("H", 2, "uint16"),
    "int32": ("i", 4, "int32"),
    "uint32": ("I", 4, "uint32"),
    "int64": ("q", 8, "int64"),
    "uint64": ("Q", 8, "uint64"),
    "float32": ("f", 4, "float32"),
    "float64": ("d", 8, "float64"),
}
_HEADER = "std_msgs/Header"


def dds_topic_name(resolved_name: str) -> str:
    """ROS 1 resolved topic name to the DDS topic name ROS 2 uses: ``/chatter`` -> ``rt/chatter``."""
    return "rt/" + resolved_name.lstrip("/")


def dds_type_name(ros_type: str) -> str:
    """ROS type to ROS 2's DDS type name: ``std_msgs/String`` -> ``std_msgs::msg::dds_::String_``."""
    if ros_type == "time":
        return "builtin_interfaces::msg::dds_::Time_"
    if ros_type == "duration":
        return "builtin_interfaces::msg::dds_::Duration_"
    pkg, _, name = ros_type.partition("/")
    return f"{pkg}::msg::dds_::{name}_"


def _field_name(name: str) -> str:
    # ROS 2 requires lower-case field names; the rename happened exactly this way
    # for the messages that had upper-case ones (CameraInfo D K R P, ...).
    return name.lower()


#: message classes built at run time from a definition (``genpy.dynamic``), by ROS type: the nested types of a
#: type whose package is not installed (see :func:`register_message_classes`)
_runtime_classes: Dict[str, Type[genpy.Message]] = {}


def register_message_classes(classes: Dict[str, Type[genpy.Message]]) -> None:
    """Make classes built at run time (``genpy.dynamic.generate_dynamic``'s answer) known to the DDS mapping,
    for types whose package is not installed: a nested field of such a type is looked up here."""
    with _idl_lock:
        for ros_type, cls in classes.items():
            _runtime_classes.setdefault(ros_type, cls)


def _msg_class(ros_type: str) -> Type[genpy.Message]:
    if ros_type == "Header":
        ros_type = _HEADER
    # run-time classes first: roslib looks for a package that is not installed for ~0.7 s on every call
    cls: Optional[Type[genpy.Message]] = _runtime_classes.get(ros_type) or roslib.message.get_message_class(ros_type)
    if cls is None:
        raise TypeMappingError(f"cannot load the ROS message class {ros_type!r}: is its package installed?")
    return cls


def _fields(cls: Any) -> List[Tuple[str, str]]:
    """(ros field name, slot type) in wire order; Header loses its seq as in ROS 2."""
    pairs = list(zip(cls.__slots__, cls._slot_types))
    if getattr(cls, "_type", None) == _HEADER:
        pairs = [p for p in pairs if p[0] != "seq"]
    return pairs


# ---------------------------------------------------------------------------
# IdlStruct generation (for Topic creation and discovery type information)

_idl_lock = threading.RLock()
_idl_cache: Dict[str, Any] = {}


def _idl_class(ros_type: str) -> Any:
    import_cyclonedds()
    from cyclonedds.idl import make_idl_struct
    from cyclonedds.idl import types as _t

    t: Any = _t

    with _idl_lock:
        if ros_type in _idl_cache:
            return _idl_cache[ros_type]
        if ros_type in TIME_TYPES:
            fields: Dict[str, Any] = {"sec": t.int32, "nanosec": t.uint32}
        else:
            cls = _msg_class(ros_type)
            fields = {}
            for name, slot_type in _fields(cls):
                base, is_array, length = parse_slot_type(slot_type)
                if base in _PRIMS:
                    elem: Any = getattr(t, _PRIMS[base][2]) if _PRIMS[base][2] != "bool" else bool
                elif base == "string":
                    elem = str
                else:
                    elem = None
                if elem is None:
                    if base in TIME_TYPES:
                        sub = base
                    else:
                        sub = _msg_class(base)._type
                    elem = _idl_class(sub)
                if is_array:
                    elem = t.array[elem, length] if length is not None else t.sequence[elem]
                fields[_field_name(name)] = elem
        typename = dds_type_name(ros_type)
        cls_name = typename.replace("::", "_")
        idl = make_idl_struct(cls_name, typename, fields)
        # what the XTypes bytes of this class depend on (dds.typecache): the mapping and the definition
        definition = "" if ros_type in TIME_TYPES else f"{cls._md5sum}\n{getattr(cls, '_full_text', '')}"
        setattr(idl, "__micros_rt_xtypes_key__", type_key(idl, f"{ros_type}\n{fields!r}\n{definition}"))
        _idl_cache[ros_type] = idl
        return idl


# ---------------------------------------------------------------------------
# Codec generation

class _Source:
    def __init__(self) -> None:
        self.lines: List[str] = []
        self.indent = 1
        self.consts: Dict[str, Any] = {}
        self.counter = 0

    def emit(self, line: str) -> None:
        self.lines.append("    " * self.indent + line)

    def const(self, value: Any, prefix: str = "K") -> str:
        self.counter += 1
        name = f"_{prefix}{self.counter}"
        self.consts[name] = value
        return name

    def var(self, prefix: str = "v") -> str:
        self.counter += 1
        return f"_{prefix}{self.counter}"


def _group_structs(codes: List[str], endian: str) -> List[struct.Struct]:
    """One precompiled struct per possible start offset modulo 8.

    XCDR1 aligns each primitive to its size (at most 8) relative to the payload
    start; a run of scalars therefore packs in one call once the run's start
    offset modulo 8 is known, with the padding written into the format.
    """
    out = []
    for start in range(8):
        off = start
        fmt = endian
        for c in codes:
            size = struct.calcsize(c)
            pad = (-off) % size
            fmt += "x" * pad + c
            off += pad + size
        out.append(struct.Struct(fmt))
    return out


class _CodecBuilder:
    """Walks a message class and emits encode and decode functions."""

    def __init__(self, endian: str, *, numpy_arrays: bool = False) -> None:
        self.endian = endian
        self.numpy_arrays = numpy_arrays  # decode numeric arrays as numpy arrays (rospy.numpy_msg classes)
        self.enc = _Source()
        self.dec = _Source()

    # -- walking ---------------------------------------------------------
    def _leaves(self, ros_type: str, path: str) -> List[Tuple[Any, ...]]:
        """Flatten a message into leaves: ('prim', path, code, is_bool) or ('var', kind, ...)."""
        if ros_type in TIME_TYPES:
            return [("prim", path + ".secs", "i", False), ("prim", path + ".nsecs", "I", False)]
        out: List[Tuple[Any, ...]] = []
        cls = _msg_class(ros_type)
        for name, slot_type in _fields(cls):
            p = f"{path}.{name}"
            base, is_array, length = parse_slot_type(slot_type)
            if not is_array:
                if base in _PRIMS:
                    out.append(("prim", p, _PRIMS[base][0], base == "bool"))
                elif base == "string":
                    out.append(("string", p))
                else:
                    sub = base if base in TIME_TYPES else _msg_class(base)._type
                    out.extend(self._leaves(sub, p))
            elif base in BYTES_TYPES:
                out.append(("bytes", p, length))
            elif base in _PRIMS:
                out.append(("primarray", p, _PRIMS[base][0], length, base == "bool"))
            elif base == "string":
                out.append(("strarray", p, length))
            else:
                sub = base if base in TIME_TYPES else _msg_class(base)._type
                out.append(("msgarray", p, sub, length))
        return out

    # -- encode ----------------------------------------------------------
    def _emit_count(self, v: str, path: str, length: int | None) -> None:
        """A sequence's element count, or the length check of a fixed-size array."""
        s = self.enc
        if length is None:
            s.emit("b += _Z[:(4 - len(b)) & 3]")
            s.emit(f"b += _U32.pack(len({v}))")
        else:
            s.emit(f"if len({v}) != {length}: raise _bad_len({path!r}, {length}, len({v}))")

    def encode_body(self, ros_type: str, path: str) -> None:
        s = self.enc
        run: List[Tuple[str, str]] = []

        def flush() -> None:
            if not run:
                return
            structs = s.const(_group_structs([c for _, c in run], self.endian), "G")
            s.emit(f"b += {structs}[(len(b) - 4) & 7].pack({', '.join(p for p, _ in run)})")
            run.clear()

        for leaf in self._leaves(ros_type, path):
            kind = leaf[0]
            if kind == "prim":
                run.append((leaf[1], leaf[2]))
                continue
            flush()
            p = leaf[1]
            if kind == "string":
                v = s.var()
                s.emit(f"{v} = {p}")
                s.emit(f"{v} = {v}.encode() if {v}.__class__ is str else _str_bytes({v})")
                s.emit("b += _Z[:(4 - len(b)) & 3]")
                s.emit(f"b += _U32.pack(len({v}) + 1)")
                s.emit(f"b += {v}")
                s.emit("b.append(0)")
            elif kind == "bytes":
                v = s.var()
                s.emit(f"{v} = {p}")
                s.emit(f"if {v}.__class__ is not bytes: {v} = _as_bytes({v})")
                self._emit_count(v, p, leaf[2])
                s.emit(f"b += {v}")
            elif kind == "primarray":
                _, p, code, length, is_bool = leaf
                size = struct.calcsize(code)
                v = s.var()
                s.emit(f"{v} = {p}")
                self._emit_count(v, p, length)
                s.emit(f"if len({v}):")  # len(): an ndarray has no truth value
                s.emit(f"    b += _Z[:(4 - len(b)) & {size - 1}]")
                # values that already hold the wire's bytes go in as a block: a 1-D numpy array of the field's
                # exact dtype (bool[]: numpy's bool, one byte 0/1 each), an array.array of its typecode. Any
                # other value is converted, and range-checked, element by element, as genpy does
                blocks: List[Tuple[str, str]] = []
                if numpy is not None:
                    dt = s.const(numpy.dtype(numpy.bool_) if is_bool else numpy.dtype(self.endian + code), "D")
                    blocks.append((f"{v}.__class__ is _NDARRAY and {v}.dtype == {dt} and {v}.ndim == 1",
                                   f"b += {v}.tobytes()"))
                codes = _array_codes(code) if not is_bool and self.endian == "<" else ""
                if codes:
                    blocks.append((f"{v}.__class__ is _ARRAY and {v}.typecode in {codes!r}", f"b += {v}"))
                pack = f"b += _pack('{self.endian}%d{code}' % len({v}), *{v})"
                for i, (condition, block) in enumerate(blocks):
                    s.emit(f"    {'elif' if i else 'if'} {condition}:")
                    s.emit(f"        {block}")
                if blocks:
                    s.emit("    else:")
                    s.emit(f"        {pack}")
                else:
                    s.emit(f"    {pack}")
            elif kind == "strarray":
                _, p, length = leaf
                v, x = s.var(), s.var("x")
                s.emit(f"{v} = {p}")
                self._emit_count(v, p, length)
                s.emit(f"for {x} in {v}:")
                s.emit(f"    {x} = {x}.encode() if {x}.__class__ is str else _str_bytes({x})")
                s.emit("    b += _Z[:(4 - len(b)) & 3]")
                s.emit(f"    b += _U32.pack(len({x}) + 1)")
                s.emit(f"    b += {x}")
                s.emit("    b.append(0)")
            elif kind == "msgarray":
                _, p, sub, length = leaf
                v, x = s.var(), s.var("x")
                s.emit(f"{v} = {p}")
                self._emit_count(v, p, length)
                s.emit(f"for {x} in {v}:")
                s.indent += 1
                self.encode_body(sub, x)
                s.indent -= 1
        flush()

    # -- decode ----------------------------------------------------------
    def _new(self, ros_type: str) -> str:
        cls: Any = genpy.Time if ros_type == "time" else genpy.Duration if ros_type == "duration" \
            else _msg_class(ros_type)
        return self.dec.const(cls, "C")

    def decode_body(self, ros_type: str, target: str) -> None:
        """Emit code that fills the already created object ``target``."""
        s = self.dec
        if ros_type in TIME_TYPES:
            fields: List[Tuple[str, str]] = [("secs", "int32"), ("nsecs", "uint32")]
        else:
            cls = _msg_class(ros_type)
            fields = list(zip(cls.__slots__, cls._slot_types))
        run: List[Tuple[str, str, bool]] = []  # (path, code, is_bool)

        def flush() -> None:
            if not run:
                return
            structs = s.const(_group_structs([c for _, c, _ in run], self.endian), "G")
            st = s.var("s")
            s.emit(f"{st} = {structs}[(p - 4) & 7]")
            names = [s.var() for _ in run]
            s.emit(f"{', '.join(names)}{',' if len(names) == 1 else ''} = {st}.unpack_from(buf, p)")
            s.emit(f"p += {st}.size")
            for name, (path, _, is_bool) in zip(names, run):
                s.emit(f"{path} = {'bool(' + name + ')' if is_bool else name}")
            run.clear()

        def walk_scalars(rtype: str, obj: str) -> None:
            # nested fixed parts are flattened into the current run, objects created first
            if rtype in TIME_TYPES:
                run.append((obj + ".secs", "i", False))
                run.append((obj + ".nsecs", "I", False))
                return
            self_fields = list(zip(_msg_class(rtype).__slots__, _msg_class(rtype)._slot_types))
            for fname, ftype in self_fields:
                handle(rtype, fname, ftype, obj)

        def handle(owner_type: str, name: str, slot_type: str, obj: str) -> None:
            p = f"{obj}.{name}"
            if owner_type == _HEADER and name == "seq":
                s.emit(f"{p} = 0")  # set per publisher by the subscriber
                return
            base, is_array, length = parse_slot_type(slot_type)
            if not is_array:
                if base in _PRIMS:
                    run.append((p, _PRIMS[base][0], base == "bool"))
                elif base == "string":
                    flush()
                    n = s.var("n")
                    s.emit("p += (4 - p) & 3")
                    s.emit(f"{n}, = _U32.unpack_from(buf, p)")
                    s.emit(f"if {n} > len(buf) - p - 4: raise _bad_count({n}, len(buf) - p - 4, p)")
                    s.emit(f"{p} = buf[p + 4:p + 3 + {n}].decode()")
                    s.emit(f"p += 4 + {n}")
                else:
                    sub = base if base in TIME_TYPES else _msg_class(base)._type
                    c = self._new(sub)
                    s.emit(f"{p} = {c}.__new__({c})")
                    walk_scalars(sub, p)
                return
            flush()
            n = s.var("n")
            if length is None:
                s.emit("p += (4 - p) & 3")
                s.emit(f"{n}, = _U32.unpack_from(buf, p)")
                s.emit("p += 4")
                # a length beyond the sample is malformed: refuse before looping or allocating
                s.emit(f"if {n} > len(buf) - p: raise _bad_count({n}, len(buf) - p, p)")
            else:
                s.emit(f"{n} = {length}")
            if base in BYTES_TYPES:
                s.emit(f"{p} = bytes(buf[p:p + {n}])")
                s.emit(f"p += {n}")
            elif base in _PRIMS:
                code = _PRIMS[base][0]
                size = struct.calcsize(code)
                s.emit(f"if {n}:")
                s.emit(f"    p += (4 - p) & {size - 1}" if size > 1 else "    pass")
                if self.numpy_arrays and base != "bool":
                    # rospy.numpy_msg: a numpy array viewing the received sample, as rospy's frombuffer gives;
                    # from a big-endian sample a native copy, as rospy's (its TCPROS side writes raw bytes)
                    dt = s.const(numpy.dtype(self.endian + code), "D")
                    if self.endian == "<" and sys.byteorder == "little":
                        s.emit(f"{p} = _frombuffer(buf, {dt}, {n}, p)")
                    else:
                        native = s.const(numpy.dtype(code), "D")
                        s.emit(f"{p} = _frombuffer(buf, {dt}, {n}, p).astype({native})")
                else:
                    s.emit(f"{p} = _unpack_from('{self.endian}%d{code}' % {n}, buf, p)")
                if base == "bool":
                    s.emit(f"{p} = [bool(_q) for _q in {p}]")
                elif length is None:
                    pass
                s.emit(f"p += {n} * {size}")
            elif base == "string":
                lst, i, m = s.var("l"), s.var("i"), s.var("m")
                s.emit(f"{lst} = []")
                s.emit(f"for {i} in range({n}):")
                s.emit("    p += (4 - p) & 3")
                s.emit(f"    {m}, = _U32.unpack_from(buf, p)")
                s.emit(f"    if {m} > len(buf) - p - 4: raise _bad_count({m}, len(buf) - p - 4, p)")
                s.emit(f"    {lst}.append(buf[p + 4:p + 3 + {m}].decode())")
                s.emit(f"    p += 4 + {m}")
                s.emit(f"{p} = {lst}")
            else:
                sub = base if base in TIME_TYPES else _msg_class(base)._type
                c = self._new(sub)
                lst, i, x = s.var("l"), s.var("i"), s.var("x")
                s.emit(f"{lst} = []")
                s.emit(f"for {i} in range({n}):")
                s.indent += 1
                s.emit(f"{x} = {c}.__new__({c})")
                self.decode_body(sub, x)
                s.emit(f"{lst}.append({x})")
                s.indent -= 1
                s.emit(f"{p} = {lst}")

        for fname, ftype in fields:
            if ros_type in TIME_TYPES:
                run.append((f"{target}.{fname}", "i" if fname == "secs" else "I", False))
            else:
                handle(ros_type, fname, ftype, target)
        flush()


def _as_bytes(value: Any) -> bytes:
    if isinstance(value, int):  # bytes(5) would be 5 NUL bytes
        raise TypeError(f"expected bytes or a sequence of ints 0..255, got {type(value).__name__}")
    try:
        return bytes(value)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"expected bytes or a sequence of ints 0..255, got {type(value).__name__}") from exc


def _str_bytes(value: Any) -> bytes:
    # a string field takes str (encoded UTF-8) or bytes, as genpy does; bytes(123) would be 123 NUL bytes
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    raise TypeError(f"expected str, got {type(value).__name__}")


def _bad_count(n: int, left: int, offset: int) -> ValueError:
    return ValueError(f"a sequence of {n} elements at offset {offset} does not fit in the {left} bytes left")


def _bad_len(path: str, expected: int, got: int) -> ValueError:
    return ValueError(f"field {path.split('.', 1)[-1]}: fixed-size array needs {expected} elements, got {got}")


def _array_codes(struct_code: str) -> str:
    """The ``array.array`` typecodes whose items have the size and kind of ``struct_code``'s (on Linux
    ``'q'`` and ``'l'`` are both 8 bytes), or ``''`` on a big-endian host (then no array takes the fast path)."""
    if sys.byteorder != "little":
        return ""
    size = struct.calcsize(struct_code)
    kind = "f" if struct_code in "fd" else "u" if struct_code.isupper() else "i"
    return "".join(tc for tc in "bBhHiIlLqQfd"
                   if array.array(tc).itemsize == size
                   and ("f" if tc in "fd" else "u" if tc.isupper() else "i") == kind)


_COMMON = {
    "_Z": bytes(8),
    "_ARRAY": array.array,
    "_NDARRAY": numpy.ndarray if numpy is not None else None,
    "_frombuffer": numpy.frombuffer if numpy is not None else None,
    "_U32": struct.Struct("<I"),
    "_pack": struct.pack,
    "_unpack_from": struct.unpack_from,
    "_as_bytes": _as_bytes,
    "_str_bytes": _str_bytes,
    "_bad_count": _bad_count,
    "_bad_len": _bad_len,
}

_CDR_LE = b"\x00\x01\x00\x00"
_CDR_BE = b"\x00\x00\x00\x00"


def _compile(name: str, src: _Source, header: str, footer: str, extra: Dict[str, Any]) -> Callable[..., Any]:
    code = header + "\n" + "\n".join(src.lines) + "\n" + footer
    namespace: Dict[str, Any] = dict(_COMMON)
    namespace.update(extra)
    namespace.update(src.consts)
    exec(compile(code, f"<micros_rt codec {name}>", "exec"), namespace)
    return namespace[name]  # type: ignore[no-any-return]


@dataclass(frozen=True)
class DDSType:
    """A ROS 1 message class with its DDS type name, IdlStruct and CDR codec.

    ``encode(msg) -> bytes`` gives a complete serialized sample (encapsulation
    header included); ``decode(data) -> msg`` reads one, little or big endian.
    """

    ros_type: str
    md5sum: str
    data_class: Type[genpy.Message]
    type_name: str
    idl_class: Any
    encode: Callable[[Any], bytes]
    decode: Callable[[bytes], Any]


_ENCODE_ERRORS = (struct.error, TypeError, ValueError, AttributeError, OverflowError, UnicodeError)
_DECODE_ERRORS = (struct.error, IndexError, ValueError, TypeError, AttributeError, OverflowError, MemoryError,
                  RecursionError)

# genpy packs bool as uint8: any value 0..255 serializes (the one table of ranges is micros_rt.rostypes)
_INT_RANGES: Dict[str, Tuple[int, int]] = {**INT_RANGES, "bool": (0, 255)}


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _bad_scalar(base: str, value: Any) -> str | None:
    if numpy is not None and isinstance(value, numpy.bool_):
        value = bool(value)
    if base in _INT_RANGES:
        lo, hi = _INT_RANGES[base]
        if not isinstance(value, numbers.Integral):  # numpy's integers too
            return f"{_short(value)} is not an integer ({base}: {lo}..{hi})"
        if not lo <= int(value) <= hi:
            return f"{_short(value)} is out of range ({base}: {lo}..{hi})"
        return None
    if base in FLOAT_TYPES:
        return None if isinstance(value, numbers.Real) else f"{_short(value)} is not a number ({base})"
    if base == "string":
        if isinstance(value, (bytes, bytearray)):
            return None
        if not isinstance(value, str):
            return f"{_short(value)} is not a string"
        try:
            value.encode()
        except UnicodeError:
            return f"{_short(value)} cannot be encoded as UTF-8"
    return None


_SEQUENCES = (list, tuple, array.array) + ((numpy.ndarray,) if numpy is not None else ())


def describe_bad_field(msg: Any, ros_type: str, path: str = "") -> str | None:
    """The first field of ``msg`` whose value cannot be serialized, in words (``field header.stamp.secs:
    8589934592 is out of range (int32: ...)``), or None when none is found. Slow; only for error messages."""
    if ros_type in TIME_TYPES:
        fields = [("secs", "int32" if ros_type == "duration" else "uint32"), ("nsecs", "int32" if ros_type ==
                                                                               "duration" else "uint32")]
    else:
        cls = _msg_class(ros_type)
        if not _is_a(msg, cls):
            return f"field {path or '(message)'}: {_short(msg)} is not a {ros_type}"
        fields = list(zip(cls.__slots__, cls._slot_types))
    for name, slot_type in fields:
        where = f"{path}.{name}" if path else name
        value = getattr(msg, name, None)
        base, is_array, length = parse_slot_type(slot_type)
        if base == "Header":
            base = _HEADER
        if is_array:
            if base in BYTES_TYPES and isinstance(value, (bytes, bytearray)):
                items: List[Any] = []
            elif not isinstance(value, _SEQUENCES) and not (base in BYTES_TYPES and isinstance(value, (bytes,
                                                                                                     bytearray))):
                return f"field {where}: {_short(value)} is not a list"
            elif getattr(value, "ndim", 1) != 1:
                return f"field {where}: a numpy array of {getattr(value, 'ndim')} dimensions, where one is needed"
            else:
                items = list(value[:1000])
            if length is not None and len(value) != length:
                return f"field {where}: fixed-size array needs {length} elements, got {len(value)}"
            for i, item in enumerate(items):
                problem = _describe_value(item, base, f"{where}[{i}]")
                if problem:
                    return problem
            continue
        problem = _describe_value(value, base, where)
        if problem:
            return problem
    return None


def _describe_value(value: Any, base: str, where: str) -> str | None:
    if base in _PRIMS or base == "string":
        problem = _bad_scalar(base, value)
        return f"field {where}: {problem}" if problem else None
    if base in TIME_TYPES:
        if not isinstance(value, (genpy.Time, genpy.Duration)):
            return f"field {where}: {_short(value)} is not a {base}"
        return describe_bad_field(value, base, where)
    sub = _msg_class(base)
    if not _is_a(value, sub):
        return f"field {where}: {_short(value)} is not a {sub._type}"
    return describe_bad_field(value, sub._type, where)


def _is_a(value: Any, cls: Type[genpy.Message]) -> bool:
    """``value`` is a ``cls`` message: that class, or another class of the same type and definition (a run-time
    class of a type that is also installed, e.g. the std_msgs/Header a run-time type nests)."""
    return isinstance(value, cls) or (isinstance(value, genpy.Message) and getattr(value, "_type", None) == cls._type
                                      and getattr(value, "_md5sum", None) == cls._md5sum)


def is_numpy_msg(data_class: Any) -> bool:
    """Whether ``data_class`` is a ``rospy.numpy_msg.numpy_msg(...)`` class: its numeric arrays are numpy arrays.

    >>> from std_msgs.msg import Float32MultiArray
    >>> from rospy.numpy_msg import numpy_msg
    >>> is_numpy_msg(Float32MultiArray), is_numpy_msg(numpy_msg(Float32MultiArray))
    (False, True)
    """
    return getattr(getattr(data_class, "deserialize", None), "__module__", None) == "rospy.numpy_msg"


_cache: Dict[type, DDSType] = {}
_cache_lock = threading.Lock()


def dds_type_for(data_class: Type[genpy.Message]) -> DDSType:
    """The DDS mapping of a genpy message class (cached per class).

    >>> from std_msgs.msg import String
    >>> dds_type_for(String).type_name
    'std_msgs::msg::dds_::String_'
    """
    with _cache_lock:
        found = _cache.get(data_class)
    if found is not None:
        return found
    ros_type = getattr(data_class, "_type", None)
    if not isinstance(ros_type, str) or not hasattr(data_class, "_slot_types"):
        raise TypeMappingError(f"{data_class!r} is not a genpy (ROS 1) message class")
    try:
        enc_builder = _CodecBuilder("<")
        enc_builder.encode_body(ros_type, "msg")
        encode_fields = _compile(
            "encode", enc_builder.enc,
            "def encode(msg):\n    b = bytearray(_HDR)", "    return b\n",  # bytes-like: Cyclone takes it without another copy
            {"_HDR": _CDR_LE},
        )

        def encode(msg: Any) -> bytes:
            try:
                return encode_fields(msg)  # type: ignore[no-any-return]
            except _ENCODE_ERRORS as exc:
                raise genpy.SerializationError(
                    f"cannot serialize {ros_type}: {describe_bad_field(msg, ros_type) or exc}") from exc

        decoders = []
        numpy_arrays = is_numpy_msg(data_class)
        for endian in "<>":
            b = _CodecBuilder(endian, numpy_arrays=numpy_arrays)
            b.dec.consts["_CLS"] = data_class
            b.decode_body(ros_type, "m")
            extra = {"_U32": struct.Struct(endian + "I")}
            decoders.append(_compile(
                "decode_body", b.dec,
                "def decode_body(buf):\n    p = 4\n    m = _CLS.__new__(_CLS)", "    return m\n", extra,
            ))
        decode_le, decode_be = decoders

        def decode(data: bytes) -> Any:
            kind = data[:2]
            try:
                if kind == b"\x00\x01":
                    return decode_le(data)
                if kind == b"\x00\x00":
                    return decode_be(data)
            except _DECODE_ERRORS as exc:
                raise MalformedSampleError(f"malformed CDR sample for {ros_type} ({len(data)} bytes): {exc}") from exc
            raise MalformedSampleError(
                f"unsupported CDR encapsulation {data[:2].hex()} for {ros_type} (micros_rt reads plain CDR, XCDR1, "
                "as ROS 2 writes it)")

        idl = _idl_class(ros_type)
    except TypeMappingError:
        raise
    except Exception as exc:  # generator bugs or exotic definitions: say which type
        raise TypeMappingError(f"cannot map ROS type {ros_type!r} to DDS: {exc}") from exc
    result = DDSType(
        ros_type=ros_type,
        md5sum=getattr(data_class, "_md5sum", ""),
        data_class=data_class,
        type_name=dds_type_name(ros_type),
        idl_class=idl,
        encode=encode,
        decode=decode,
    )
    with _cache_lock:
        _cache[data_class] = result
    return result
