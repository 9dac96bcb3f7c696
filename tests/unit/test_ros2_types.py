"""ROS 1 classes of ROS 2-only types from the ROS 2 installation's definitions (micros_rt/ros2_types.py): the
rewriting rules, the md5 ROS 1 computes, refusals naming the field, and the modules stock tools import."""

from __future__ import annotations

import re
from pathlib import Path
import pytest

from micros_rt.ros2_types import (Ros2TypeError, _Converter, idl_to_ros2_text, ros2_action_class,
                                  ros2_message_class, ros2_service_class, write_python_modules)

ROOT = Path(__file__).resolve().parents[2]
ROS2_PYTHON = str(ROOT / ".venv-ros2" / "bin" / "python")


def _write(share: Path, rel: str, text: str) -> None:
    path = share / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_ros2_syntax_maps_back_to_ros1() -> None:
    """Defaults dropped, bounds made unbounded, builtin_interfaces as time/duration, Header as ROS 1's, constants
    kept (a bool's true as True, a string's quotes removed, its '#' kept)."""
    converter = _Converter([])
    text = converter.text("# a comment\nint32 order 5  # a default value\nstring<=8 name\nint32[<=4] few\n"
                          "float64[3] xyz\nbuiltin_interfaces/Time stamp\nbuiltin_interfaces/Duration span\n"
                          "std_msgs/Header header\nint8 MODE=2  # a constant\nbool ON=true\nstring NAME=\"a#b\"\n",
                          "pkg", "x")
    assert text == ("int32 order\nstring name\nint32[] few\nfloat64[3] xyz\ntime stamp\nduration span\n"
                    "Header header\nint8 MODE=2\nbool ON=True\nstring NAME=a#b\n"), text
    assert "std_msgs/Header" in converter.deps   # a nested installed type's ROS 1 definition comes with it


def test_what_cannot_be_mapped_is_refused_naming_the_field(tmp_path: Path) -> None:
    _write(tmp_path, "r2pkg/msg/Inner.msg", "wstring label\n")
    _write(tmp_path, "r2pkg/msg/Outer.msg", "int32 a\nInner inner\n")
    for bad, words in (("wstring w", r"field w \(wstring\): ROS 1 has no wstring"),
                       ("NoSuchType t", r"field t \(NoSuchType\).*pkg/msg/NoSuchType is not installed"),
                       ("r2pkg/Outer o", r"Inner.msg: field label \(wstring\)"),
                       # ROS 1's installed geometry_msgs/Point has x, y, z: a ROS 2 type of that name with other
                       # fields would be misread on the wire
                       ("geometry_msgs/Point p", None)):
        if words is None:
            _write(tmp_path, "geometry_msgs/msg/Point.msg", "float64 x\nfloat64 y\n")
            words = "field p .*installed geometry_msgs/Point has the fields x, y, z, ROS 2's .* has x, y"
        with pytest.raises(Ros2TypeError, match=words):
            _Converter([tmp_path]).text(bad, "pkg", "x")


def test_nested_ros2_only_types_are_built_in_turn_with_ros1s_md5(tmp_path: Path) -> None:
    _write(tmp_path, "r2pkg/msg/Inner.msg", "uint8 level\nstring<=4 code\n")
    _write(tmp_path, "r2pkg/msg/Outer.msg", "std_msgs/Header header\nInner[<=3] inners\nr2pkg/Inner one\n"
           "builtin_interfaces/Time stamp\n")
    python = str(tmp_path / "bin" / "python")   # the share directory beside a ROS 2 helper's python
    (tmp_path / "share").mkdir()
    (tmp_path / "r2pkg").rename(tmp_path / "share" / "r2pkg")
    outer = ros2_message_class("r2pkg/msg/Outer", python=python)
    inner = ros2_message_class("r2pkg/msg/Inner", python=python)
    assert outer._type == "r2pkg/Outer" and outer._has_header and outer.__slots__ == ["header", "inners", "one", "stamp"]
    import genmsg  # type: ignore[import-untyped]
    import genmsg.msg_loader  # type: ignore[import-untyped]
    from std_msgs.msg import Header

    # the md5 ROS 1 gives the same definitions written as ROS 1 .msg files
    context = genmsg.MsgContext.create_default()
    context.register("std_msgs/Header", genmsg.msg_loader.load_msg_from_string(context, Header._full_text,
                                                                               "std_msgs/Header"))
    context.register("r2pkg/Inner", genmsg.msg_loader.load_msg_from_string(context, "uint8 level\nstring code\n",
                                                                           "r2pkg/Inner"))
    spec = genmsg.msg_loader.load_msg_from_string(context, "Header header\nInner[] inners\nInner one\ntime stamp\n",
                                                  "r2pkg/Outer")
    assert outer._md5sum == genmsg.compute_md5(context, spec)
    assert inner._md5sum == genmsg.compute_md5(context, context.get_registered("r2pkg/Inner"))
    msg = outer(inners=[inner(level=3, code="ab")])
    assert msg.inners[0].level == 3


def test_test_msgs_types_come_from_the_ros2_installation_and_their_modules_are_written(tmp_path: Path) -> None:
    """(Stock tools importing the written modules: tests/integration/test_relay_ros2.py, `rostopic echo`.)"""
    basic = ros2_message_class("test_msgs/msg/BasicTypes", python=ROS2_PYTHON)
    assert len(basic.__slots__) == 13 and basic._md5sum == "629d43a4b526fc75b794a6c186a25f31"
    srv = ros2_service_class("test_msgs/srv/BasicTypes", python=ROS2_PYTHON)
    assert srv._md5sum == "3298567a01d6a550bc47afa0165da4fd"   # tests/peers/ros1_srv_types.py's, built with genmsg
    _action, source = ros2_action_class("test_msgs/action/NestedMessage", python=ROS2_PYTHON)
    assert source.startswith("built from") and source.endswith("NestedMessage.action")
    with pytest.raises(Ros2TypeError, match="WStrings.msg: field wstring_value"):
        ros2_message_class("test_msgs/msg/WStrings", python=ROS2_PYTHON)
    assert "test_msgs" in write_python_modules(tmp_path)
    written = tmp_path / "test_msgs"
    assert {"_BasicTypes.py", "_NestedMessageAction.py"} <= {p.name for p in (written / "msg").iterdir()}
    assert "from ._BasicTypes import *" in (written / "srv" / "__init__.py").read_text()
    assert f'_md5sum = "{basic._md5sum}"' in (written / "msg" / "_BasicTypes.py").read_text()


def test_installed_ros1_packages_win() -> None:
    from std_msgs.msg import String

    assert ros2_message_class("std_msgs/msg/String") is String
    with pytest.raises(ValueError, match="not a ROS 2 srv type"):
        ros2_service_class("std_srvs/msg/SetBool")



def _constants_and_fields(ros1_text: str) -> "tuple[list[str], list[str]]":
    # genmsg's md5 puts constants first, whatever their place: compare them apart
    lines = ros1_text.splitlines()
    constants = sorted(line for line in lines if re.match(r"^\S+ \w+=", line))
    return constants, [line for line in lines if line not in constants]


def test_every_idl_of_the_ros2_installation_reads_back_as_its_definition() -> None:
    """A type defined only as .idl is read from it: each .idl the ROS 2 installation has beside a .msg, .srv or
    .action gives the same ROS 1 definition (IDL has no ``char``: a .msg's char is uint8 there)."""
    share = Path(ROS2_PYTHON).parent.parent / "share"
    compared = 0
    for kind in ("msg", "srv", "action"):
        for idl in sorted(share.glob(f"*/{kind}/*.idl")):
            source, pkg = idl.with_suffix(f".{kind}"), idl.parent.parent.name
            try:
                want = [_Converter([share]).text(part, pkg, str(source))
                        for part in re.split(r"^---\s*$", source.read_text(), flags=re.M)]
            except Ros2TypeError:
                continue   # what ROS 1 cannot hold (wstring): refused from either file
            got = [_Converter([share]).text(part, pkg, str(idl))
                   for part in idl_to_ros2_text(idl.read_text(), kind, idl.stem, str(idl)).split("---\n")]
            want = [re.sub(r"^char(\[|\s)", r"uint8\1", part, flags=re.M) for part in want]
            assert [_constants_and_fields(p) for p in got] == [_constants_and_fields(p) for p in want], idl
            compared += 1
    assert compared > 100, compared   # std_msgs, geometry_msgs, sensor_msgs, test_msgs, action_msgs, ...


def test_a_type_defined_only_as_idl_is_built_from_it(tmp_path: Path) -> None:
    share = tmp_path / "share"
    _write(share, "idlpkg/msg/Reading.idl", '#include "builtin_interfaces/msg/Time.idl"\n'
           "module idlpkg {\n  module msg {\n    module Reading_Constants {\n      const uint8 OK = 1;\n"
           '      const string LABEL = "a // b";\n    };\n    typedef double double__3[3];\n'
           '    @verbatim (language="comment", text=\n      "one reading (see http://x)")\n'
           "    struct Reading {\n      builtin_interfaces::msg::Time stamp;\n\n      @default (value=2)\n"
           "      uint8 status;\n\n      double__3 xyz;\n\n      sequence<float, 8> samples;\n\n"
           "      string<16> name;\n    };\n  };\n};\n")
    cls = ros2_message_class("idlpkg/msg/Reading", python=str(tmp_path / "bin" / "python"))
    assert cls.__slots__ == ["stamp", "status", "xyz", "samples", "name"] and cls.OK == 1 and cls.LABEL == "a // b"
    import genmsg
    import genmsg.msg_loader

    context = genmsg.MsgContext.create_default()
    spec = genmsg.msg_loader.load_msg_from_string(
        context, "uint8 OK=1\nstring LABEL=a // b\ntime stamp\nuint8 status\nfloat64[3] xyz\nfloat32[] samples\n"
                 "string name\n", "idlpkg/Reading")
    assert cls._md5sum == genmsg.compute_md5(context, spec)
