"""Services between graphs: the exporting relay announces where a service of its graph is served, the importing
relay offers it in its own graph and forwards each call there.

The announcement is a DDS writer on :data:`ANNOUNCE_TOPIC` whose micros_rt tag names the graph, the service,
its type and md5 and its server's ``rosrpc://`` address (nothing is ever written on it: discovery carries the
tag, and the writer's disappearance withdraws it). The importing relay's ``rospy.Service`` forwards each
request to that address over ROS 1's own service protocol (TCPROS, one connection per call, with a timeout):
the server's host must be reachable from the importing robot, as the DDS traffic's is. A failure is an error
in words to the caller (``rosservice call`` prints it).
"""

from __future__ import annotations

import io
import socket
import struct
from typing import Any, Dict, Tuple, Type
from urllib.parse import urlparse

import genpy

from micros_rt.exceptions import MicrosRtError

__all__ = ["ANNOUNCE_TOPIC", "ServiceCallError", "call_service", "encode_header", "probe_service", "read_header"]

#: the DDS topic (ROS name) whose writers' tags announce exported services
ANNOUNCE_TOPIC = "/_micros_rt_relay/services"


class ServiceCallError(MicrosRtError):
    """A forwarded service call that did not return a response; the message says why."""


def encode_header(fields: Dict[str, str]) -> bytes:
    """A ROS 1 connection header (TCPROS, services and topics alike): length-prefixed ``key=value`` fields."""
    body = b"".join(struct.pack("<I", len(item)) + item
                    for item in (f"{k}={v}".encode() for k, v in fields.items()))
    return struct.pack("<I", len(body)) + body


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    chunks = []
    while n:
        chunk = sock.recv(min(n, 1 << 20))
        if not chunk:
            raise ServiceCallError("the peer closed the connection")
        chunks.append(chunk)
        n -= len(chunk)
    return b"".join(chunks)


def read_header(sock: socket.socket) -> Dict[str, str]:
    """The peer's connection header from ``sock``; :class:`ServiceCallError` when the peer closed first."""
    (size,) = struct.unpack("<I", _recv_exact(sock, 4))
    body = _recv_exact(sock, size)
    fields: Dict[str, str] = {}
    i = 0
    while i < len(body):
        (n,) = struct.unpack("<I", body[i:i + 4])
        key, _, value = body[i + 4:i + 4 + n].decode("utf-8", "replace").partition("=")
        fields[key] = value
        i += 4 + n
    return fields


def _address(uri: str) -> Tuple[str, int]:
    parsed = urlparse(uri)
    if parsed.scheme != "rosrpc" or not parsed.hostname or not parsed.port:
        raise ServiceCallError(f"{uri!r} is not a rosrpc://host:port address")
    return parsed.hostname, parsed.port


def call_service(uri: str, service: str, service_class: Any, request: genpy.Message, *, caller_id: str,
                 timeout: float) -> genpy.Message:
    """Call ``service`` (a ``rospy`` service class, e.g. ``std_srvs.srv.SetBool``) at ``uri``
    (``rosrpc://host:port``) with ``request``; the response, or :class:`ServiceCallError` in words."""
    host, port = _address(uri)
    response_class: Type[genpy.Message] = service_class._response_class
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            sock.sendall(encode_header({"callerid": caller_id, "service": service,
                                         "md5sum": service_class._md5sum, "type": service_class._type,
                                         "persistent": "0"}))
            header = read_header(sock)
            if "error" in header:
                raise ServiceCallError(f"the server refused the connection: {header['error']}")
            out = io.BytesIO()
            request.serialize(out)
            data = out.getvalue()
            sock.sendall(struct.pack("<I", len(data)) + data)
            ok = _recv_exact(sock, 1)
            (size,) = struct.unpack("<I", _recv_exact(sock, 4))
            payload = _recv_exact(sock, size)
    except socket.timeout:
        raise ServiceCallError(f"no answer from {host}:{port} within {timeout:g} s") from None
    except OSError as exc:
        raise ServiceCallError(f"cannot reach the server at {host}:{port}: {exc}") from None
    if ok != b"\x01":
        raise ServiceCallError(f"the server's handler failed: {payload.decode('utf-8', 'replace')}")
    response = response_class()
    try:
        response.deserialize(payload)
    except (genpy.DeserializationError, struct.error, ValueError) as exc:
        raise ServiceCallError(f"the server's response is not a valid {response_class._type}: {exc}") from None
    return response


def probe_service(uri: str, service: str, *, caller_id: str, timeout: float) -> Dict[str, str]:
    """The server's connection header for ``service`` at ``uri`` (``type``, ``md5sum``, ...), asked as
    ``rosservice`` does (a ``probe`` connection, no call)."""
    host, port = _address(uri)
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            sock.sendall(encode_header({"callerid": caller_id, "service": service, "md5sum": "*", "probe": "1"}))
            return read_header(sock)
    except socket.timeout:
        raise ServiceCallError(f"no answer from {host}:{port} within {timeout:g} s") from None
    except OSError as exc:
        raise ServiceCallError(f"cannot reach the server at {host}:{port}: {exc}") from None
