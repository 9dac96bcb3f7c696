"""Run-time message types of the relay (micros_rt.bridges.relay.msgtypes): classes built from a definition,
checked against the announced md5, usable by the DDS mapping with their nested types."""

from __future__ import annotations

from typing import Any

import genpy.dynamic
import pytest

from micros_rt.bridges.relay.msgtypes import (TypeLearningError, class_from_definition, definition_field,
                                              installed_class)
from micros_rt.transports.dds.types import dds_type_for

TYPE = "mrt_unit/Reading"
DEFINITION = """\
string data
mrt_unit/Sample[] samples
================================================================================
MSG: mrt_unit/Sample
float64 value
uint8[] raw
"""


def reference() -> Any:
    return genpy.dynamic.generate_dynamic(TYPE, DEFINITION)[TYPE]


def test_a_class_built_from_the_tag_field_carries_nested_types_over_dds() -> None:
    ref = reference()
    field = definition_field(ref)
    assert ";" not in field and "=" not in field   # fits a micros_rt writer tag
    cls = class_from_definition(TYPE, ref._md5sum, field, compressed=True)
    assert cls._md5sum == ref._md5sum and cls._type == TYPE
    sample_cls = genpy.dynamic.generate_dynamic(TYPE, DEFINITION)["mrt_unit/Sample"]
    msg = cls(data="x", samples=[sample_cls(value=2.5, raw=b"\x01\x02")])
    dds = dds_type_for(cls)
    back = dds.decode(bytes(dds.encode(msg)))
    assert back.data == "x" and back.samples[0].value == 2.5 and bytes(back.samples[0].raw) == b"\x01\x02"
    assert class_from_definition(TYPE, ref._md5sum, field, compressed=True) is cls  # built once


def test_installed_types_are_never_built() -> None:
    from std_msgs.msg import String

    assert installed_class("std_msgs/String") is String
    assert installed_class(TYPE) is None and installed_class("not a type") is None


@pytest.mark.parametrize("md5, field, words", [
    ("0" * 32, None, "gives md5"),                     # another definition than the publisher announced
    ("", "!!not base64 zlib!!", "is damaged"),
    ("", "", "no definition"),
])
def test_a_bad_definition_is_refused_in_words(md5: str, field: "str | None", words: str) -> None:
    with pytest.raises(TypeLearningError, match=words):
        class_from_definition("mrt_unit/Bad", md5, definition_field(reference()) if field is None else field,
                              compressed=True)


def test_a_definition_that_does_not_parse_says_which_type() -> None:
    with pytest.raises(TypeLearningError, match="mrt_unit/Broken"):
        class_from_definition("mrt_unit/Broken", "", "flaot64 x y z\n")


def test_a_raw_service_class_keeps_requests_and_responses_as_the_bytes_on_the_wire() -> None:
    import io

    from rospy.impl.tcpros_service import convert_return_to_response

    from micros_rt.bridges.relay.msgtypes import raw_service_class

    srv = raw_service_class("mrt_unit/AddTwo", "89e34646fc8b65917a3b40a500d657d8")
    assert (srv._type, srv._md5sum) == ("mrt_unit/AddTwo", "89e34646fc8b65917a3b40a500d657d8")
    assert (srv._request_class._type, srv._response_class._type) == ("mrt_unit/AddTwoRequest",
                                                                     "mrt_unit/AddTwoResponse")
    wire = bytes(range(17))
    request = srv._request_class().deserialize(wire)
    out = io.BytesIO()
    request.serialize(out)
    assert out.getvalue() == wire
    response = srv._response_class().deserialize(b"\x2a" + bytes(8))
    assert convert_return_to_response(response, srv._response_class) is response  # rospy's server takes it
    for type_name, md5 in (("mrt_unit/AddTwo", ""), ("mrt_unit/AddTwo", "*"), ("AddTwo", "89e3")):
        with pytest.raises(TypeLearningError, match="cannot be carried as bytes"):
            raw_service_class(type_name, md5)
