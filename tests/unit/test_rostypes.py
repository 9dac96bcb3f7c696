"""The one slot-type parser (micros_rt.rostypes.parse_slot_type) that the DDS, MQTT and microcontroller codecs
read genpy's ``_slot_types`` with."""

from __future__ import annotations

import doctest
import importlib
import re
from typing import Iterator, List, Optional, Tuple

import genmsg.msgs  # type: ignore[import-untyped]
import genpy
import pytest

import micros_rt.rostypes
from micros_rt.rostypes import BYTES_TYPES, INT_RANGES, SlotType, parse_slot_type

_PRIMITIVES = [*INT_RANGES, "bool", "float32", "float64", "string", "time", "duration"]


@pytest.mark.parametrize("base", _PRIMITIVES + ["Header", "std_msgs/Header", "geometry_msgs/Point"])
def test_every_element_type_as_a_value_a_sequence_and_a_fixed_array(base: str) -> None:
    assert parse_slot_type(base) == SlotType(base, False, None)
    assert parse_slot_type(f"{base}[]") == SlotType(base, True, None)
    assert parse_slot_type(f"{base}[9]") == SlotType(base, True, 9)
    assert parse_slot_type(f"{base}[0]") == SlotType(base, True, 0)


@pytest.mark.parametrize("slot_type, is_bytes", [
    ("uint8[]", True), ("char[]", True), ("uint8[4]", True), ("char[16]", True),
    ("uint8", False), ("char", False), ("int8[]", False), ("byte[]", False), ("string[]", False),
])
def test_bytes_are_the_arrays_of_uint8_and_char(slot_type: str, is_bytes: bool) -> None:
    assert parse_slot_type(slot_type).is_bytes is is_bytes
    assert BYTES_TYPES == ("uint8", "char")


def test_the_parts_unpack_in_order() -> None:
    base, is_array, length = parse_slot_type("float64[36]")
    assert (base, is_array, length) == ("float64", True, 36)


@pytest.mark.parametrize("slot_type", ["float64[x]", "int32[-]", "string[1.5]"])
def test_an_array_length_that_is_not_a_number_is_refused_naming_the_type(slot_type: str) -> None:
    with pytest.raises(ValueError, match=re.escape(repr(slot_type)) + ".*not a number"):
        parse_slot_type(slot_type)


def _installed_slot_types() -> Iterator[str]:
    for module in ("std_msgs.msg", "geometry_msgs.msg", "sensor_msgs.msg", "nav_msgs.msg", "rosgraph_msgs.msg",
                   "diagnostic_msgs.msg", "visualization_msgs.msg", "trajectory_msgs.msg", "actionlib_msgs.msg"):
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        for name in dir(mod):
            cls = getattr(mod, name)
            if isinstance(cls, type) and issubclass(cls, genpy.Message) and cls is not genpy.Message:
                yield from getattr(cls, "_slot_types")


def test_every_installed_message_field_reads_as_genmsg_reads_it() -> None:
    seen: List[Tuple[str, Tuple[str, bool, Optional[int]]]] = []
    for slot_type in set(_installed_slot_types()):
        expected = genmsg.msgs.parse_type(slot_type)
        assert tuple(parse_slot_type(slot_type)) == expected, slot_type
        seen.append((slot_type, expected))
    assert len(seen) > 50                       # std_msgs, geometry_msgs and sensor_msgs at least
    assert any(length is not None for _, (_, _, length) in seen)   # fixed arrays (CameraInfo's K[9], ...)


def test_the_module_examples_hold() -> None:
    failed, tried = doctest.testmod(micros_rt.rostypes)
    assert (failed, tried > 0) == (0, True)
