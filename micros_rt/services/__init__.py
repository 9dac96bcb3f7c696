"""Services in both worlds: one handler serves ROS 1 and ROS 2 clients, one client reaches either kind of server.

:meth:`micros_rt.NodeHandle.advertise_service` and :meth:`micros_rt.NodeHandle.service_client` are the public
entry points; docs/services.md tells how it works and what it costs. The ROS 1 side is rospy's own
``rospy.Service``/``rospy.ServiceProxy`` (TCPROS through the master); the ROS 2 side is an rclpy helper process
(:mod:`micros_rt.services.gateway`), because Cyclone DDS cannot carry the request identity that Fast DDS's ROS 2
services need (see :mod:`micros_rt.services.ros2_helper`).
"""

from __future__ import annotations

from typing import Any, Callable, Optional

from ..transports.tcpros import patches
from ..core.runtime import _require_node
from .client import ServiceClient
from .errors import ServiceError, ServiceTimeoutError, ServiceUnavailableError
from . import gateway as _gateway
from .gateway import Ros2Gateway, Ros2Unavailable, close_gateway
from .mapping import check_srv_class, dds_service_topics, srv_mapping
from .server import ServiceServer

__all__ = [
    "ServiceClient",
    "ServiceServer",
    "ServiceError",
    "ServiceTimeoutError",
    "ServiceUnavailableError",
    "Ros2Unavailable",
    "advertise_service",
    "service_client",
    "ros2_gateway",
    "close_gateway",
    "dds_service_topics",
    "srv_mapping",
]


def _process_gateway() -> Ros2Gateway:
    return _gateway.gateway(patches.caller_id())


def ros2_gateway() -> Ros2Gateway:
    """This process's ROS 2 helper, started on first use (:class:`Ros2Unavailable`, in words, when it cannot be):
    for a program that serves or calls services on the ROS 2 side only, with its own ROS 1 side (the relay's
    ``ros2:`` section). ``advertise(name, ros2_type, handler)``, ``prepare_client``, ``server_ready``, ``call``."""
    return _process_gateway()


def advertise_service(resolved_name: str, srv_class: Any, handler: Callable[[Any], Any], *,
                      ros2: bool = True, ros1: bool = True) -> ServiceServer:
    """Serve ``resolved_name`` to ROS 1 (``ros1=False``: the caller does, the drop-in ``rospy.Service``) and
    (``ros2=True``) ROS 2 clients with ``handler(request) -> response``."""
    _require_node()
    check_srv_class(srv_class)
    if not callable(handler):
        raise TypeError(f"handler must be callable, got {handler!r}")
    return ServiceServer(resolved_name, srv_class, handler, _process_gateway, ros2=ros2, ros1=ros1)


def service_client(resolved_name: str, srv_class: Any, *, timeout: Optional[float] = None,
                   ros2: bool = True) -> ServiceClient:
    """A callable client of ``resolved_name`` that reaches a ROS 1 or (``ros2=True``) a ROS 2 server."""
    _require_node()
    check_srv_class(srv_class)
    return ServiceClient(resolved_name, srv_class, _process_gateway, timeout=timeout, ros2=ros2)
