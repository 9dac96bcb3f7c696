"""ROS 1 service classes for the service peers (stock rospy and micros_rt; never rclpy): std_srvs as installed,
and test_msgs/BasicTypes, which has no ROS 1 package, built at run time from the same definition as ROS 2's
test_msgs/srv/BasicTypes (a user's srv, mapped at run time)."""

from __future__ import annotations

import importlib
from typing import Any, Dict

import genmsg  # type: ignore[import-untyped]
import genmsg.msg_loader  # type: ignore[import-untyped]
import genpy.dynamic

BASIC_FIELDS = ("bool bool_value\nbyte byte_value\nchar char_value\nfloat32 float32_value\nfloat64 float64_value\n"
                "int8 int8_value\nuint8 uint8_value\nint16 int16_value\nuint16 uint16_value\nint32 int32_value\n"
                "uint32 uint32_value\nint64 int64_value\nuint64 uint64_value\nstring string_value\n")
RUNTIME = {"test_msgs/BasicTypes": BASIC_FIELDS + "---\n" + BASIC_FIELDS}
_made: Dict[str, Any] = {}


def runtime_srv(ros_type: str, text: str) -> Any:
    context = genmsg.MsgContext.create_default()
    md5 = genmsg.compute_md5(context, genmsg.msg_loader.load_srv_from_string(context, text, ros_type))
    request_text, response_text = text.split("---\n")
    request = genpy.dynamic.generate_dynamic(ros_type + "Request", request_text)[ros_type + "Request"]
    response = genpy.dynamic.generate_dynamic(ros_type + "Response", response_text)[ros_type + "Response"]
    return type(ros_type.split("/")[1], (), {"_type": ros_type, "_md5sum": md5, "_request_class": request,
                                             "_response_class": response})


def srv_class(ros_type: str) -> Any:
    """'std_srvs/SetBool' -> its class; run-time ones from RUNTIME."""
    if ros_type in RUNTIME:
        if ros_type not in _made:
            _made[ros_type] = runtime_srv(ros_type, RUNTIME[ros_type])
        return _made[ros_type]
    pkg, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{pkg}.srv"), name)


def msg_class(ros_type: str) -> Any:
    pkg, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def fields(msg: Any) -> Dict[str, Any]:
    return {k: getattr(msg, k) for k in msg.__slots__}


def answer(who: str, srv_type: str, request: Any, response_class: Any) -> Any:
    """The peers' common server behaviour: SetBool echoes data (and refuses False when it is told to fail),
    Trigger says who, BasicTypes echoes every field."""
    if srv_type == "std_srvs/SetBool":
        if not request.data and who.endswith("!"):
            raise RuntimeError(f"{who.rstrip('!')} refuses False")
        return response_class(success=request.data, message=f"{who.rstrip('!')} got {request.data}")
    if srv_type == "std_srvs/Trigger":
        return response_class(success=True, message=f"{who.rstrip('!')} triggered")
    return response_class(**fields(request))
