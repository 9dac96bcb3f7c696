"""ROS 1 field types as the codecs need them: one table and one slot-type parser for every codec (DDS CDR,
MQTT JSON and text, the microcontroller's MessagePack), so a range, a type name or the reading of
``float64[9]`` is defined once. Pure: no genpy state.

>>> INT_RANGES["uint8"], parse_slot_type("float32[3]"), parse_slot_type("uint8[]").is_bytes
((0, 255), SlotType(base='float32', is_array=True, length=3), True)
"""

from __future__ import annotations

from typing import Dict, NamedTuple, Optional, Tuple

__all__ = ["BYTES_TYPES", "FLOAT_TYPES", "INT_RANGES", "SlotType", "TIME_TYPES", "parse_slot_type"]

#: Integer types (``byte`` and ``char`` are ROS 1's deprecated aliases of int8 and uint8) and their ranges.
INT_RANGES: Dict[str, Tuple[int, int]] = {
    "int8": (-2**7, 2**7 - 1), "byte": (-2**7, 2**7 - 1),
    "uint8": (0, 2**8 - 1), "char": (0, 2**8 - 1),
    "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1),
}
FLOAT_TYPES = ("float32", "float64")
TIME_TYPES = ("time", "duration")
#: Element types whose arrays genpy holds as ``bytes`` (``uint8[]``, ``char[]``, and their fixed-size forms).
BYTES_TYPES = ("uint8", "char")


class SlotType(NamedTuple):
    """One entry of a genpy class's ``_slot_types``, taken apart (see :func:`parse_slot_type`)."""

    #: the element type: a primitive, ``time``/``duration``, ``string``, or a message (``pkg/Type``, ``Header``)
    base: str
    #: True for ``T[]`` and ``T[N]``
    is_array: bool
    #: ``N`` of a fixed-size array ``T[N]``; None for ``T[]`` and for a single value
    length: Optional[int]

    @property
    def is_bytes(self) -> bool:
        """True for an array genpy holds as ``bytes`` (``uint8[]``, ``char[4]``, ...)."""
        return self.is_array and self.base in BYTES_TYPES


def parse_slot_type(slot_type: str) -> SlotType:
    """A genpy slot type taken apart: ``'float64[9]'`` -> ``('float64', True, 9)``, ``'string[]'`` ->
    ``('string', True, None)``, ``'std_msgs/Header'`` -> ``('std_msgs/Header', False, None)``.

    >>> base, is_array, length = parse_slot_type("geometry_msgs/Point[]")
    >>> base, is_array, length
    ('geometry_msgs/Point', True, None)
    """
    if not slot_type.endswith("]"):
        return SlotType(slot_type, False, None)
    base, _, size = slot_type[:-1].partition("[")
    try:
        return SlotType(base, True, int(size) if size else None)
    except ValueError:
        raise ValueError(f"{slot_type!r} is not a ROS slot type: the array length is not a number") from None
