"""The errors of services: each a :class:`~micros_rt.exceptions.MicrosRtError` and what rospy raises in its place,
so ``except rospy.ServiceException`` (and ``rospy.ROSException`` for a wait that timed out) keep working."""

from __future__ import annotations

import rospy

from ..exceptions import MicrosRtError

__all__ = ["ServiceError", "ServiceUnavailableError", "ServiceTimeoutError"]


class ServiceError(MicrosRtError, rospy.ServiceException):  # type: ignore[misc]
    """A service call failed; the message names the service, the side (ROS 1 or ROS 2) and why, with the
    server's own words when it raised."""


class ServiceUnavailableError(ServiceError):
    """No server of the service is registered with the ROS master nor discovered on ROS 2."""


class ServiceTimeoutError(ServiceError, rospy.ROSException):  # type: ignore[misc]
    """No answer (or, for ``wait_for_service``, no server) within the caller's timeout."""
