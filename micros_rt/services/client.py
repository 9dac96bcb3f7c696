"""A service client that reaches a ROS 1 server through the master or a ROS 2 server through DDS discovery.

Which side answers is decided per call: a server registered with the ROS master first (a micros_rt server is
registered there too, so two micros_rt nodes talk TCPROS), else a ROS 2 server the ROS 2 helper discovered. The
decision is kept for :data:`ROUTE_TTL` seconds, then looked up again.
"""

from __future__ import annotations

import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor, TimeoutError as FutureTimeout
from typing import Any, Callable, Optional

import genpy
import rosgraph.masterapi
import rospy

from ..exceptions import TypeMappingError
from ..transports.tcpros import patches
from .errors import ServiceError, ServiceTimeoutError, ServiceUnavailableError
from .gateway import Ros2Gateway, Ros2Unavailable, ros2_present
from .mapping import SrvMapping, srv_mapping

__all__ = ["ServiceClient", "ROUTE_TTL"]

#: seconds a call keeps the side (ROS 1 or ROS 2) the previous call found, before asking the master again
ROUTE_TTL = 1.0
_POLL = 0.05
_UNSET: Any = object()
ROS1, ROS2 = "ROS 1", "ROS 2"

_ros1_calls = ThreadPoolExecutor(max_workers=8, thread_name_prefix="micros_rt ROS 1 call")


class ServiceClient:
    """What :meth:`micros_rt.NodeHandle.service_client` returns; call it like a ``rospy.ServiceProxy``.

    >>> set_flag = nh.service_client("set_flag", SetBool, timeout=2.0)   # doctest: +SKIP
    >>> set_flag.wait_for_service(5.0); set_flag(True).success            # doctest: +SKIP
    True
    """

    def __init__(self, resolved_name: str, srv_class: Any, gateway: Callable[[], Ros2Gateway], *,
                 timeout: Optional[float] = None, ros2: bool = True) -> None:
        if timeout is not None and not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds or None, got {timeout!r}")
        self.resolved_name = resolved_name
        self.srv_class = srv_class
        self.request_class = srv_class._request_class
        self.response_class = srv_class._response_class
        self.timeout = timeout
        self._ros1 = patches.ROSPY_SERVICE_PROXY(resolved_name, srv_class)  # rospy's own (micros-rt run)
        self._route: Optional[str] = None
        self._route_time = 0.0
        self._gateway: Optional[Ros2Gateway] = None
        self._mapping: Optional[SrvMapping] = None
        self.ros2_error: Optional[str] = None if ros2 else "not requested (ros2=False)"
        self._ros2_started = threading.Event()
        self.closed = False
        #: the ROS 2 side not started: no ROS 2 peer on the DDS domain yet (``MICROS_RT_ROS2=auto``); looked for
        #: again when the client looks for its server
        self._ros2_deferred: Optional[Callable[[], Ros2Gateway]] = None
        self._defer_lock = threading.Lock()
        if ros2:
            self._ros2_deferred = gateway
            self._kick_ros2()
        else:
            self._ros2_started.set()

    def _kick_ros2(self) -> None:
        """Start the ROS 2 side once a ROS 2 peer may be on the domain (a ``stat`` while none is)."""
        if self._ros2_deferred is None or not ros2_present():
            return
        with self._defer_lock:
            gateway, self._ros2_deferred = self._ros2_deferred, None
        if gateway is not None:
            # the helper takes about a second to start: discovery of a ROS 2 server runs meanwhile
            threading.Thread(target=self._start_ros2, args=(gateway,), name="micros_rt service client",
                             daemon=True).start()

    def _start_ros2(self, gateway: Callable[[], Ros2Gateway]) -> None:
        try:
            mapping = srv_mapping(self.srv_class)
            gw = gateway()
            gw.prepare_client(self.resolved_name, mapping.ros2_type)
            self._mapping, self._gateway = mapping, gw
        except (Ros2Unavailable, TypeMappingError) as exc:
            self.ros2_error = str(exc)
        finally:
            self._ros2_started.set()

    # -- finding the server -------------------------------------------------------------------------------------
    def _ros1_registered(self) -> bool:
        try:
            rosgraph.masterapi.Master(rospy.get_name()).lookupService(self.resolved_name)
            return True
        except rosgraph.masterapi.Error:
            return False   # not registered
        except Exception:
            return False   # the master is unreachable: rospy says so at the call

    def _ros2_ready(self) -> bool:
        gw, mapping = self._gateway, self._mapping
        if gw is None or mapping is None:
            return False
        try:
            return gw.server_ready(self.resolved_name, mapping.ros2_type)
        except Ros2Unavailable as exc:
            self.ros2_error = str(exc)
            return False

    def _find_route(self) -> Optional[str]:
        now = time.monotonic()
        if self._route is not None and now - self._route_time < ROUTE_TTL:
            return self._route
        self._kick_ros2()  # a route kept needs no ROS 2 side started: no stat per call
        route = ROS1 if self._ros1_registered() else ROS2 if self._ros2_ready() else None
        self._route, self._route_time = route, now
        return route

    def wait_for_service(self, timeout: Optional[float] = None) -> None:
        """Block until a ROS 1 or ROS 2 server of the service is there; ServiceTimeoutError (a
        ``rospy.ROSException``) after ``timeout`` seconds, as ``rospy.wait_for_service``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            self._route = None
            self._kick_ros2()
            if self._ros1_registered():
                return
            if self._ros2_started.is_set() and self._ros2_ready():
                return
            if deadline is not None and time.monotonic() >= deadline:
                raise ServiceTimeoutError(
                    f"timeout exceeded while waiting for service {self.resolved_name} ({timeout:g} s): no ROS 1 "
                    f"server registered with the master, no ROS 2 server discovered{self._ros2_note()}")
            if rospy.is_shutdown():
                raise ServiceError(f"the node shut down while waiting for service {self.resolved_name}")
            time.sleep(_POLL)

    def _ros2_note(self) -> str:
        if self._ros2_deferred is not None:
            return " (no ROS 2 node on the DDS domain)"
        if not self._ros2_started.is_set():
            return " (the ROS 2 helper is still starting)"
        return f" (ROS 2 unreachable: {self.ros2_error})" if self.ros2_error else ""

    # -- calling ------------------------------------------------------------------------------------------------
    def _request(self, args: Any, kwargs: Any) -> Any:
        if len(args) == 1 and not kwargs and isinstance(args[0], genpy.Message):
            if not isinstance(args[0], self.request_class):
                raise TypeError(f"service {self.resolved_name} takes a {self.request_class._type}, "
                                f"got a {args[0]._type}")
            return args[0]
        try:
            return self.request_class(*args, **kwargs)
        except (TypeError, AttributeError) as exc:
            raise TypeError(f"service {self.resolved_name} takes a {self.request_class._type} or its fields "
                            f"({', '.join(self.request_class.__slots__) or 'none'}): {exc}") from exc

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """``client(request)`` or ``client(field values...)``: the response, as ``rospy.ServiceProxy``."""
        return self.call(*args, **kwargs)

    def call(self, *args: Any, timeout: Any = _UNSET, **kwargs: Any) -> Any:
        """One call; ``timeout`` (seconds, None: wait for ever) overrides the client's. Raises TypeError for a
        request of the wrong type, ServiceTimeoutError, ServiceUnavailableError or ServiceError in words."""
        if self.closed:
            raise ServiceError(f"service client {self.resolved_name} is closed")
        request = self._request(args, kwargs)
        limit = self.timeout if timeout is _UNSET else timeout
        started = time.monotonic()
        route = self._find_route()
        if route is None and self._ros2_deferred is None and not self._ros2_started.is_set():
            # the helper is starting: a ROS 2 server may be found when it is up
            self._ros2_started.wait(limit)
            self._route = None
            route = self._find_route()
        if route is None:
            raise ServiceUnavailableError(
                f"service {self.resolved_name} is not available: no ROS 1 server registered with the master, "
                f"no ROS 2 server discovered{self._ros2_note()}")
        left = None if limit is None else max(0.001, limit - (time.monotonic() - started))
        if route == ROS1:
            return self._call_ros1(request, left)
        return self._call_ros2(request, left, limit)

    def _call_ros1(self, request: Any, timeout: Optional[float]) -> Any:
        try:
            if timeout is None:
                return self._ros1.call(request)
            future = _ros1_calls.submit(self._ros1.call, request)
            try:
                return future.result(timeout)
            except FutureTimeout:
                # rospy's call has no timeout: it ends when the server answers or its connection closes
                raise ServiceTimeoutError(f"service {self.resolved_name}: the ROS 1 server did not answer within "
                                          f"{timeout:g} s") from None
        except rospy.ServiceException as exc:
            self._route = None  # look the server up again next time
            if isinstance(exc, ServiceError):
                raise
            # rospy puts the server's words in as a bytes repr: "responded with an error: b'...'"
            words = re.sub(r"\bb'(.*)'$", r"\1", str(exc))
            raise ServiceError(f"service {self.resolved_name} (ROS 1): {words}") from exc

    def _call_ros2(self, request: Any, timeout: Optional[float], limit: Optional[float]) -> Any:
        gw, mapping = self._gateway, self._mapping
        assert gw is not None and mapping is not None
        try:
            body = mapping.encode_request(request)
        except genpy.SerializationError as exc:
            raise TypeError(f"service {self.resolved_name}: {exc}") from exc
        try:
            answer = gw.call(self.resolved_name, mapping.ros2_type, body, timeout)
        except TimeoutError:
            raise ServiceTimeoutError(f"service {self.resolved_name}: the ROS 2 server did not answer within "
                                      f"{limit:g} s") from None
        except (RuntimeError, Ros2Unavailable) as exc:
            self._route = None
            raise ServiceError(f"service {self.resolved_name} (ROS 2): {exc}") from exc
        try:
            return mapping.decode_response(answer)
        except Exception as exc:
            raise ServiceError(f"service {self.resolved_name} (ROS 2): the response does not decode as "
                               f"{self.response_class._type}: {exc}") from exc

    @property
    def side(self) -> Optional[str]:
        """Which side answered the last call: ``"ROS 1"``, ``"ROS 2"`` or None before a call."""
        return self._route

    def close(self) -> None:
        """Stop using the client (the ROS 2 helper's client stays for the process); harmless twice."""
        self.closed = True
        self._ros1.close()

    def __enter__(self) -> "ServiceClient":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<ServiceClient {self.resolved_name} ({self.srv_class._type})>"
