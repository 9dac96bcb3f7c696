"""A service served to ROS 1 clients (rospy's own ``rospy.Service``, TCPROS through the master) and to ROS 2
clients (the ROS 2 helper's rclpy service, :mod:`micros_rt.services.gateway`), with one handler."""

from __future__ import annotations

import threading
from typing import Any, Callable, Optional

import genpy
import rospy

from ..exceptions import TypeMappingError
from ..log import nonblocking_logger
from ..transports.tcpros import patches
from .gateway import Ros2Gateway, Ros2Unavailable, when_ros2_present
from .mapping import SrvMapping, srv_mapping

__all__ = ["ServiceServer", "as_response"]

_log = nonblocking_logger("rosout.micros_rt.services")


def as_response(value: Any, response_class: Any) -> Any:
    """A handler's return value as ``response_class``, as rospy accepts it: the response itself, a dict of its
    fields, a tuple/list of them in order, or the value of a one-field response. TypeError in words otherwise."""
    if isinstance(value, response_class):
        return value
    if value is None:
        raise TypeError(f"the handler returned None, not a {response_class._type}")
    if isinstance(value, genpy.Message):
        raise TypeError(f"the handler returned a {value._type}, not a {response_class._type}")
    if isinstance(value, dict):
        return response_class(**value)
    if isinstance(value, (list, tuple)):
        return response_class(*value)
    if len(response_class.__slots__) == 1:
        return response_class(value)
    raise TypeError(f"the handler returned {value!r}, not a {response_class._type} (or a dict or tuple of its fields)")


class ServiceServer:
    """What :meth:`micros_rt.NodeHandle.advertise_service` returns: ``shutdown()`` (or ``close()``) withdraws the
    service from both sides. ``ros2_error`` says, in words, why ROS 2 clients are not served (None: they are, or
    will be: under ``MICROS_RT_ROS2=auto`` the ROS 2 side, an rclpy helper process, starts once a ROS 2 node is on
    the DDS domain, ``ros2_waiting`` until then)."""

    def __init__(self, resolved_name: str, srv_class: Any, handler: Callable[[Any], Any],
                 gateway: Callable[[], Ros2Gateway], *, ros2: bool = True, ros1: bool = True) -> None:
        self.resolved_name = resolved_name
        self.srv_class = srv_class
        self.handler = handler
        self.ros2_error: Optional[str] = "not requested (ros2=False)" if not ros2 else None
        self._gateway: Optional[Ros2Gateway] = None
        self._mapping: Optional[SrvMapping] = None
        self._lock = threading.Lock()
        self.closed = False
        # rospy's own class (``micros-rt run`` replaces the name ``rospy.Service``); none when the caller serves
        # ROS 1 itself (the drop-in rospy.Service)
        self._ros1 = patches.ROSPY_SERVICE(resolved_name, srv_class, handler) if ros1 else None
        #: the ROS 2 side waits for a ROS 2 peer on the DDS domain (``MICROS_RT_ROS2=auto``: no helper before)
        self.ros2_waiting = False
        self._gateway_factory = gateway
        if ros2:
            try:
                self._mapping = srv_mapping(srv_class)
            except TypeMappingError as exc:
                self.ros2_error = str(exc)
                _log.warning("micros_rt: service %s is served to ROS 1 clients only: %s", resolved_name, exc)
            else:
                self.ros2_waiting = True
                when_ros2_present.run(self._start_ros2)

    def _start_ros2(self) -> None:
        """Offer the service to ROS 2 clients through the process's helper (started now if it is not)."""
        mapping = self._mapping
        assert mapping is not None
        try:
            if self.closed:
                return
            gw = self._gateway_factory()
            gw.advertise(self.resolved_name, mapping.ros2_type, self._serve_ros2)
            with self._lock:
                if not self.closed:
                    self._gateway = gw
                    return
            gw.unadvertise(self.resolved_name)  # shut down meanwhile
        except Ros2Unavailable as exc:
            self.ros2_error = str(exc)
            _log.warning("micros_rt: service %s is served to ROS 1 clients only: %s", self.resolved_name, exc)
        finally:
            self.ros2_waiting = False

    @property
    def serves_ros2(self) -> bool:
        """Whether ROS 2 clients reach this service."""
        return self._gateway is not None and not self.closed

    def _serve_ros2(self, body: bytes) -> bytes:
        mapping = self._mapping
        assert mapping is not None
        try:
            request = mapping.decode_request(body)
            response = as_response(self.handler(request), self.srv_class._response_class)
            return mapping.encode_response(response)
        except Exception as exc:
            # ROS 2's service protocol has no error reply: the ROS 2 client sees its own timeout; say why here
            _log.warning("micros_rt: service %s: the handler failed on a ROS 2 client's request (%s: %s); ROS 2 "
                         "services carry no error, so that client gets no response", self.resolved_name,
                         type(exc).__name__, exc)
            raise

    def shutdown(self, reason: str = "") -> None:
        """Withdraw the service from the master and from ROS 2; harmless twice."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
        when_ros2_present.cancel(self._start_ros2)
        if self._ros1 is not None:
            self._ros1.shutdown(reason or "micros_rt ServiceServer.shutdown()")
        if self._gateway is not None:
            self._gateway.unadvertise(self.resolved_name)

    close = shutdown

    def __enter__(self) -> "ServiceServer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    def __repr__(self) -> str:
        sides = [side for side, on in (("ROS 1", self._ros1 is not None), ("ROS 2", self.serves_ros2),
                                       ("ROS 2 once a ROS 2 node is on the domain", self.ros2_waiting)) if on]
        return f"<ServiceServer {self.resolved_name} ({self.srv_class._type}) {' + '.join(sides) or 'closed'}>"
