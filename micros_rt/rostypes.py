"""ROS 1 field types as the codecs need them: one table for every codec (DDS CDR, MQTT JSON and text, the
microcontroller's MessagePack), so a range or a type name is defined once. Pure: no genpy state.

>>> INT_RANGES["uint8"], slot_base("float32[3]"), is_array("int8[]")
((0, 255), 'float32', True)
"""

from __future__ import annotations

from typing import Dict, Tuple

__all__ = ["FLOAT_TYPES", "INT_RANGES", "TIME_TYPES", "is_array", "slot_base"]

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


def slot_base(slot_type: str) -> str:
    """A genpy slot type without its array suffix: ``'float32[3]'`` -> ``'float32'``."""
    bracket = slot_type.find("[")
    return slot_type if bracket < 0 else slot_type[:bracket]


def is_array(slot_type: str) -> bool:
    """True for ``T[]`` and ``T[N]``."""
    return slot_type.endswith("]")
