"""Message types the relay carries without their package: learnt at run time, as ``rostopic echo`` does.

A relay's host need not have the message packages of the topics it carries. Every ROS 1 publisher sends its
type's full definition (``message_definition``, the ``gendeps --cat`` text) in the connection header; genpy
builds classes from that text (``genpy.dynamic``), and the DDS mapping takes them as it takes installed ones.

- **Export**: the type's package missing, :func:`learn_from_publisher` asks one publisher of the topic for its
  header (``requestTopic`` on its XML-RPC API, then a TCPROS connection with md5sum ``*`` that is closed after
  the header: no message is read) and builds the classes.
- **Between relays**: the exporting relay's writer tag carries the definition, compressed
  (:func:`definition_field`); an importing relay without the package builds the classes from it
  (:func:`class_from_definition`). The md5 the classes get must be the one the exporter announced.

Installed classes win: a type whose package is installed is never built at run time.

Services carry no definition in their headers (a server's says only ``type`` and ``md5sum``), and a relay
need not read a call to forward it: for a service type whose package is missing, :func:`raw_service_class`
gives classes that keep requests and responses as the bytes on the wire, under the announced type and md5.
"""

from __future__ import annotations

import base64
import binascii
import socket
import threading
import xmlrpc.client
import zlib
from typing import Any, Dict, List, Optional, Tuple, Type

import genpy
import roslib.message
import rospy.msg

from micros_rt.exceptions import MicrosRtError
from micros_rt.extend import TimeoutTransport
from micros_rt.ros2_types import Ros2TypeError, build_classes

from .services import ServiceCallError, encode_header, read_header

__all__ = ["TypeLearningError", "class_from_definition", "definition_field", "installed_class",
           "learn_from_publisher", "publisher_header", "raw_service_class"]



class TypeLearningError(MicrosRtError):
    """A type that could not be learnt at run time; the message says why."""


class _RawPart(rospy.msg.AnyMsg):  # type: ignore[misc]
    """A service request or response kept as its serialized bytes (``_type`` set per service)."""

    __slots__ = ()


def raw_service_class(type_name: str, md5: str) -> Any:
    """A service class for ``type_name`` (``pkg/Name``) with server md5 ``md5`` whose request and response are
    the bytes on the wire: what a relay forwards without the type's package (nothing is decoded)."""
    if not md5 or md5 == "*" or "/" not in type_name:
        raise TypeLearningError(f"service type {type_name!r} with md5 {md5!r} cannot be carried as bytes (the "
                                f"server did not announce both)")
    parts = {suffix: type(f"Raw{suffix}", (_RawPart,), {"__slots__": (), "_type": type_name + suffix,
                                                        "_md5sum": md5})
             for suffix in ("Request", "Response")}
    return type("RawService", (), {"_type": type_name, "_md5sum": md5, "_request_class": parts["Request"],
                                   "_response_class": parts["Response"]})


def installed_class(type_name: str) -> Optional[Type[genpy.Message]]:
    """The class of ``type_name`` from its installed package, or None."""
    try:
        cls = roslib.message.get_message_class(type_name)
    except (ValueError, ImportError):
        return None
    return cls if isinstance(cls, type) and issubclass(cls, genpy.Message) else None


def definition_field(data_class: Type[genpy.Message]) -> str:
    """``data_class``'s full definition, compressed and base64-encoded for a writer tag (no ``;`` or ``=``
    inside; about 1.2 kB for sensor_msgs/Image)."""
    text = str(getattr(data_class, "_full_text", "")).encode()
    return base64.b64encode(zlib.compress(text, 9)).decode().replace("=", "")


def _inflate(field: str) -> str:
    padded = field + "=" * (-len(field) % 4)
    return zlib.decompress(base64.b64decode(padded)).decode()


def class_from_definition(type_name: str, md5: str, definition: str, *,
                          compressed: bool = False) -> Type[genpy.Message]:
    """The class of ``type_name`` built from ``definition`` (the ``message_definition`` text, or a
    :func:`definition_field` when ``compressed``), checked against ``md5``; built once per (type, md5)."""
    if not definition.strip():  # e.g. an exporting relay of a micros_rt version before run-time types
        raise TypeLearningError(f"no definition of {type_name} came with it")
    try:
        text = _inflate(definition) if compressed else definition
    except (binascii.Error, zlib.error, UnicodeDecodeError, ValueError) as exc:
        raise TypeLearningError(f"the definition of {type_name} sent with it is damaged ({exc})") from None
    try:
        return build_classes(type_name, text, md5)
    except Ros2TypeError as exc:
        raise TypeLearningError(str(exc)) from None


def learn_from_publisher(master: Any, topic: str, *, caller_id: str, timeout: float = 5.0) -> Type[genpy.Message]:
    """The class of ``topic``'s type, built from the definition one of its publishers sends (``master``:
    ``rospy.get_master()``)."""
    header = publisher_header(master, topic, caller_id=caller_id, timeout=timeout)
    return class_from_definition(header.get("type", ""), header.get("md5sum", ""),
                                 header.get("message_definition", ""))


def publisher_header(master: Any, topic: str, *, caller_id: str, timeout: float = 5.0,
                     skip: Tuple[str, ...] = ()) -> Dict[str, str]:
    """The TCPROS connection header of one publisher of ``topic`` (``type``, ``md5sum``,
    ``message_definition``, ``latching``, ...), asked as ``rostopic`` does; publishers named in ``skip`` (and
    ``caller_id``) are not asked. :class:`TypeLearningError` when none answers."""
    code, msg, state = master.getSystemState()
    if code != 1:
        raise TypeLearningError(f"the master did not answer getSystemState: {msg}")
    publishers: List[str] = next((list(nodes) for name, nodes in state[0] if name == topic), [])
    failures = []
    for node in publishers:
        if node == caller_id or node in skip:
            continue
        try:
            return _publisher_header(master, node, topic, caller_id, timeout)
        except (TypeLearningError, ServiceCallError) as exc:
            failures.append(f"{node}: {exc}")
    raise TypeLearningError(f"no publisher of {topic} gave its type's definition"
                            + (f" ({'; '.join(failures)})" if failures else " (none is registered)"))


def _publisher_header(master: Any, node: str, topic: str, caller_id: str, timeout: float) -> Dict[str, str]:
    code, msg, uri = master.lookupNode(node)
    if code != 1:
        raise TypeLearningError(f"the master does not know it ({msg})")
    try:
        proxy = xmlrpc.client.ServerProxy(uri, transport=TimeoutTransport(timeout))
        answer: Any = proxy.requestTopic(caller_id, topic, [["TCPROS"]])
        code, msg, params = answer
    except (OSError, xmlrpc.client.Error) as exc:
        raise TypeLearningError(f"its API at {uri} did not answer requestTopic ({exc})") from None
    if code != 1 or not params or params[0] != "TCPROS":
        raise TypeLearningError(f"it offers no TCPROS connection ({msg})")
    host, port = str(params[1]), int(params[2])
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            sock.sendall(encode_header({"callerid": caller_id, "topic": topic, "md5sum": "*", "type": "*",
                                        "tcp_nodelay": "0"}))
            header = read_header(sock)
    except OSError as exc:
        raise TypeLearningError(f"cannot reach its TCPROS server at {host}:{port} ({exc})") from None
    if "error" in header:
        raise TypeLearningError(f"it refused the connection: {header['error']}")
    return header
