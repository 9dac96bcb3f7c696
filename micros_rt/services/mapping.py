"""A ROS 1 service class as ROS 2 sees it: names, types and the request/response codecs.

The request and response travel as ROS 2 serialized messages (CDR with its encapsulation header), encoded and
decoded by the topics' run-time DDS mapping (:func:`micros_rt.transports.dds.types.dds_type_for`), so a service
maps under the same rules as a topic (DESIGN.md, wire format) and needs nothing compiled:

* ROS 1 ``std_srvs/SetBool`` is ROS 2 ``std_srvs/srv/SetBool``; on DDS its topics are ``rq/<name>Request`` and
  ``rr/<name>Reply`` with types ``std_srvs::srv::dds_::SetBool_Request_`` and ``..._Response_``;
* an empty request or response (``std_srvs/Trigger``'s request, ``std_srvs/Empty``) is ROS 2's one-byte
  ``structure_needs_at_least_one_member``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, Type

import genpy

from ..exceptions import TypeMappingError
from ..transports.dds.types import dds_type_for, register_message_classes

__all__ = ["SrvMapping", "srv_mapping", "check_srv_class", "ros2_service_type", "dds_service_topics"]


def check_srv_class(srv_class: Any) -> None:
    """TypeError in words unless ``srv_class`` is a ROS 1 service class (``std_srvs.srv.SetBool``)."""
    ok = (isinstance(srv_class, type) and isinstance(getattr(srv_class, "_type", None), str)
          and isinstance(getattr(srv_class, "_request_class", None), type)
          and isinstance(getattr(srv_class, "_response_class", None), type))
    if not ok:
        raise TypeError(f"srv_class must be a ROS service class (e.g. std_srvs.srv.SetBool), got {srv_class!r}")


def ros2_service_type(ros_type: str) -> str:
    """``std_srvs/SetBool`` -> ``std_srvs/srv/SetBool``."""
    pkg, _, name = ros_type.partition("/")
    return f"{pkg}/srv/{name}"


def dds_service_topics(resolved_name: str, ros_type: str) -> Dict[str, str]:
    """The DDS topics and type names of ROS 2 service ``resolved_name`` (what ``ros2 service`` shows on DDS).

    >>> dds_service_topics("/set_flag", "std_srvs/SetBool")["request_topic"]
    'rq/set_flagRequest'
    """
    pkg, _, name = ros_type.partition("/")
    base = resolved_name.lstrip("/")
    return {"request_topic": f"rq/{base}Request", "reply_topic": f"rr/{base}Reply",
            "request_type": f"{pkg}::srv::dds_::{name}_Request_",
            "response_type": f"{pkg}::srv::dds_::{name}_Response_"}


_EMPTY_STRUCT = b"\x00"  # ROS 2's uint8 structure_needs_at_least_one_member


def _codec(cls: Type[genpy.Message]) -> "tuple[Callable[[Any], bytes], Callable[[bytes], Any]]":
    if not cls.__slots__:
        def encode_empty(msg: Any) -> bytes:
            return b"\x00\x01\x00\x00" + _EMPTY_STRUCT

        def decode_empty(data: bytes) -> Any:
            return cls()
        return encode_empty, decode_empty
    mapped = dds_type_for(cls)
    return mapped.encode, mapped.decode


@dataclass(frozen=True)
class SrvMapping:
    """One service class's ROS 2 form and codecs (``encode_request(msg) -> bytes`` etc.)."""

    ros_type: str
    ros2_type: str
    srv_class: Any
    encode_request: Callable[[Any], bytes]
    decode_request: Callable[[bytes], Any]
    encode_response: Callable[[Any], bytes]
    decode_response: Callable[[bytes], Any]


_cache: Dict[Any, SrvMapping] = {}
_lock = threading.Lock()


def srv_mapping(srv_class: Any) -> SrvMapping:
    """The mapping of a ROS 1 service class (cached); TypeMappingError names the type when it cannot map."""
    check_srv_class(srv_class)
    with _lock:
        found = _cache.get(srv_class)
        if found is not None:
            return found
        request, response = srv_class._request_class, srv_class._response_class
        # srv parts are not in roslib's message search path: make them known to the DDS mapping
        register_message_classes({request._type: request, response._type: response})
        try:
            enc_req, dec_req = _codec(request)
            enc_resp, dec_resp = _codec(response)
        except TypeMappingError:
            raise
        except Exception as exc:
            raise TypeMappingError(f"cannot map the service type {srv_class._type} to ROS 2: {exc}") from exc
        found = _cache[srv_class] = SrvMapping(srv_class._type, ros2_service_type(srv_class._type), srv_class,
                                               enc_req, dec_req, enc_resp, dec_resp)
        return found
