"""Actions across ROS 1 and ROS 2, both ways, with the type mapped at run time.

:meth:`micros_rt.NodeHandle.offer_action_to_ros2` makes a ROS 1 (actionlib) action server reachable by ROS 2
action clients; :meth:`micros_rt.NodeHandle.offer_ros2_action` makes a ROS 2 action server reachable by stock
actionlib clients. Both go through the process's ROS 2 helper, as services do (:mod:`micros_rt.services.gateway`);
docs/actions.md tells how and what it costs.
"""

from __future__ import annotations

from typing import Any, Optional

from ..core.runtime import _require_node
from ..services import _process_gateway
from .from_ros2 import ActionFromRos2
from .mapping import ActionMapping, action_mapping, check_action_class, ros1_to_ros2_status, ros2_to_ros1_status
from .to_ros2 import ActionToRos2

__all__ = ["ActionFromRos2", "ActionToRos2", "ActionMapping", "action_mapping", "offer_action_to_ros2",
           "offer_ros2_action", "ros1_to_ros2_status", "ros2_to_ros1_status"]


def offer_action_to_ros2(resolved_name: str, action_class: Any, *, ros2_type: Optional[str] = None,
                         accept_timeout: float = 5.0) -> ActionToRos2:
    """Make the ROS 1 action server at ``resolved_name`` reachable by ROS 2 action clients."""
    _require_node()
    check_action_class(action_class)
    return ActionToRos2(resolved_name, action_class, _process_gateway, ros2_type=ros2_type,
                        accept_timeout=accept_timeout)


def offer_ros2_action(resolved_name: str, action_class: Any, *, ros2_type: Optional[str] = None,
                      accept_timeout: float = 5.0) -> ActionFromRos2:
    """Make the ROS 2 action server of ``resolved_name`` reachable by ROS 1 (actionlib) clients."""
    _require_node()
    check_action_class(action_class)
    return ActionFromRos2(resolved_name, action_class, _process_gateway, ros2_type=ros2_type,
                          accept_timeout=accept_timeout)
