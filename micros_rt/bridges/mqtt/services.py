"""ROS services over MQTT (AimRT's mqtt RPC back end): call a service of another ROS graph through the broker.

:class:`Service` is a ``rospy.Service`` (registered with its own master, callable by stock nodes) that also
answers requests from the broker; :class:`ServiceProxy` calls it from anywhere that reaches the broker.
Both use the process's MQTT connection from the YAML profile's ``mqtt`` section (``broker``/``client``).

Wire (AimRT's): requests on ``aimrt_rpc_req/<service>``, which servers take with the MQTT 5 shared
subscription ``$share/aimrt/aimrt_rpc_req/<service>`` so that each request reaches one of several servers;
responses on ``aimrt_rpc_rsp/<client id>/<service>`` (``<service>`` URL-encoded). Request
``| n | content type | m | response topic | msg id (4) | data |``, response
``| n | content type | msg id (4) | status (4) | data |``, content type ``ros1`` (ROS 1 serialization);
a status other than 0 carries the server's error text as data.

>>> srv = Service("add", AddTwoInts, handler)                          # doctest: +SKIP
>>> ServiceProxy("add", AddTwoInts, timeout=2.0)(a=1, b=2)             # doctest: +SKIP
"""

from __future__ import annotations

import concurrent.futures
import io
import itertools
import threading
import urllib.parse
import uuid
from typing import Any, Callable, Dict, Optional, Tuple

import rospy
import rospy.topics

from ...log import nonblocking_logger
from ...ratelimit import RateLimitedLog
from ...transports.mqtt import codec
from ...transports.mqtt.client import MqttConnection

__all__ = ["Service", "ServiceProxy", "STATUS_OK", "STATUS_SERVER_ERROR", "STATUS_BAD_REQUEST"]

_log = nonblocking_logger("rosout.micros_rt.mqtt")
_problems = RateLimitedLog(_log, interval=30.0)

CONTENT_TYPE = "ros1"
STATUS_OK = 0
#: the handler raised (or returned None); the response's data is the error text
STATUS_SERVER_ERROR = 1
#: the request did not decode as the service's request type
STATUS_BAD_REQUEST = 2
QOS = 1


def _connection() -> MqttConnection:
    from ... import node_info
    from ...transports.mqtt.backend import process_backend

    node = node_info()
    profile = node.profile
    if profile is None or not getattr(profile, "mqtt", None):
        raise rospy.ROSException("services over MQTT need a broker: give init_node a YAML profile (qos_profile= or "
                                 "MICROS_RT_QOS_PROFILE) with an 'mqtt' section ('broker', 'client', 'topics')")
    return process_backend(profile, graph=node.graph, node=node.name).connection


def _func_name(name: str) -> str:
    return urllib.parse.quote(rospy.resolve_name(name), safe="")


def _decoded(decode: Callable[[bytes], Any], payload: bytes, service: str, what: str, topic: str) -> Any:
    """``decode(payload)``, or None after a warning (once per service and kind, then counted)."""
    try:
        return decode(payload)
    except codec.CodecError as exc:
        _problems.warning((service, what), f"service {service}: a {what} on '{topic}' does not decode ({exc}); "
                                           "ignored")
        return None


def _serialize(msg: Any) -> bytes:
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


class Service:
    """A rospy service that also serves requests from the broker (handlers run on a small thread pool,
    never on the MQTT network thread). ``close()`` (or ``shutdown()``) stops both."""

    def __init__(self, name: str, service_class: Any, handler: Callable[[Any], Any], *, workers: int = 4,
                 connection: Optional[MqttConnection] = None) -> None:
        self.name = rospy.resolve_name(name)
        self.service_class = service_class
        self.handler = handler
        self.served = 0
        self.ros = rospy.Service(self.name, service_class, handler)
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=workers,
                                                           thread_name_prefix=f"micros_rt mqtt srv {self.name}")
        self._conn = connection or _connection()
        self.request_topic = codec.RPC_SHARE_GROUP + codec.RPC_REQUEST_PREFIX + _func_name(name)
        self._conn.subscribe(self.request_topic, QOS, self._on_request)
        _log.info("micros_rt: service %s is also served over MQTT ('%s')", self.name, self.request_topic)

    def _on_request(self, topic: str, payload: bytes, properties: Any) -> None:
        fields = _decoded(codec.decode_rpc_request, payload, self.name, "request", topic)
        if fields is not None:
            self._pool.submit(self._serve, *fields)

    def _serve(self, content_type: str, reply_to: str, msg_id: int, data: bytes) -> None:
        if content_type != CONTENT_TYPE:
            self._reply(reply_to, msg_id, STATUS_BAD_REQUEST,
                        f"content type {content_type!r} is not supported (only {CONTENT_TYPE!r})".encode())
            return
        try:
            request = self.service_class._request_class()
            request.deserialize(data)
        except Exception as exc:  # genpy: struct.error, DeserializationError, UnicodeDecodeError
            self._reply(reply_to, msg_id, STATUS_BAD_REQUEST,
                        f"request does not decode as {self.service_class._type}: {exc}".encode())
            return
        try:
            response = self.handler(request)
            if response is None:
                raise ValueError("the service handler returned None")
            body = _serialize(response)
        except Exception as exc:  # the handler's error goes back to the caller in words, as rospy does
            self._reply(reply_to, msg_id, STATUS_SERVER_ERROR, f"error processing request: {exc}".encode())
            return
        self.served += 1
        self._reply(reply_to, msg_id, STATUS_OK, body)

    def _reply(self, reply_to: str, msg_id: int, status: int, data: bytes) -> None:
        self._conn.publish(reply_to, codec.encode_rpc_response(CONTENT_TYPE, msg_id, status, data), qos=QOS)

    def close(self) -> None:
        """Unregister from the master and the broker; harmless twice."""
        self._conn.unsubscribe(self.request_topic)
        self.ros.shutdown()
        self._pool.shutdown(wait=False)

    shutdown = close

    def __enter__(self) -> "Service":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ServiceProxy:
    """Calls a service through the broker, like ``rospy.ServiceProxy``: ``proxy(request)`` or
    ``proxy(field=value, ...)``; raises ``rospy.ServiceException`` on a timeout or a server error."""

    _ids = itertools.count(1)

    def __init__(self, name: str, service_class: Any, *, timeout: float = 5.0,
                 connection: Optional[MqttConnection] = None) -> None:
        self.name = rospy.resolve_name(name)
        self.service_class = service_class
        self.timeout = timeout
        self._conn = connection or _connection()
        client_id = self._conn.params.client.id or f"micros_rt_{uuid.uuid4().hex[:12]}"
        func = _func_name(name)
        self.request_topic = codec.RPC_REQUEST_PREFIX + func
        self.response_topic = f"{codec.RPC_RESPONSE_PREFIX}{urllib.parse.quote(client_id, safe='')}/{func}"
        self._lock = threading.Lock()
        self._pending: Dict[int, Tuple[threading.Event, list]] = {}  # type: ignore[type-arg]
        self._conn.subscribe(self.response_topic, QOS, self._on_response)

    def _on_response(self, topic: str, payload: bytes, properties: Any) -> None:
        fields = _decoded(codec.decode_rpc_response, payload, self.name, "response", topic)
        if fields is None:
            return
        _, msg_id, status, data = fields
        with self._lock:
            waiting = self._pending.pop(msg_id, None)
        if waiting is not None:           # None: it came after its call timed out
            waiting[1].extend((status, data))
            waiting[0].set()

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.call(*args, **kwargs)

    def call(self, *args: Any, **kwargs: Any) -> Any:
        """Send the request and wait (at most ``timeout`` seconds) for its response."""
        request_class = self.service_class._request_class
        if len(args) == 1 and not kwargs and isinstance(args[0], request_class):
            request = args[0]
        else:
            request = rospy.topics.args_kwds_to_message(request_class, args, kwargs)
        msg_id = next(self._ids) & 0xFFFFFFFF
        done = threading.Event()
        result: list = []  # type: ignore[type-arg]
        with self._lock:
            self._pending[msg_id] = (done, result)
        payload = codec.encode_rpc_request(CONTENT_TYPE, self.response_topic, msg_id, _serialize(request))
        sent = self._conn.publish(self.request_topic, payload, qos=QOS)
        if not sent or not done.wait(self.timeout):
            with self._lock:
                self._pending.pop(msg_id, None)
            why = "the broker is not connected" if not sent else f"no response within {self.timeout:g} s"
            raise rospy.ServiceException(
                f"service {self.name} over MQTT ({self._conn.uri}): {why}; is a server of {self.name} "
                f"({self.service_class._type}) connected to that broker?")
        status, data = result
        if status != STATUS_OK:
            raise rospy.ServiceException(f"service {self.name} over MQTT: "
                                         f"{bytes(data).decode('utf-8', 'replace') or f'status {status}'}")
        response = self.service_class._response_class()
        try:
            response.deserialize(data)
        except Exception as exc:  # genpy's decode errors
            raise rospy.ServiceException(f"service {self.name} over MQTT: the response does not decode as "
                                         f"{self.service_class._type}: {exc}") from exc
        return response

    def close(self) -> None:
        """Stop listening for responses; harmless twice."""
        self._conn.unsubscribe(self.response_topic)

    def __enter__(self) -> "ServiceProxy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
