"""A ROS 1 action class as ROS 2 sees it: the type names, the codecs of goal, result and feedback, and the goal
status codes of both sides.

ROS 1 ``test_msgs/FibonacciAction`` (with ``FibonacciGoal``, ``FibonacciResult``, ``FibonacciFeedback``) is ROS 2
``test_msgs/action/Fibonacci`` (``Goal``, ``Result``, ``Feedback``). The three parts cross the ROS 2 helper as ROS 2
serialized messages, encoded and decoded by the codec services use (:mod:`micros_rt.services.mapping`, on the topics'
run-time DDS mapping), so an action maps under the same rules as a topic and needs nothing compiled. Only the three
parts cross: the ROS 1 envelopes (``FibonacciActionGoal`` with its header and ``GoalID``) stay on the ROS 1 side,
as the ROS 2 envelopes (goal UUIDs, the action services) stay in the helper.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional

from ..exceptions import TypeMappingError
from ..services.mapping import _codec
from ..transports.dds.types import register_message_classes

__all__ = ["ActionMapping", "action_mapping", "check_action_class", "ros2_action_type", "ROS1", "ROS2",
           "ros1_to_ros2_status", "ros2_to_ros1_status", "status_name"]


class ROS1:
    """actionlib_msgs/GoalStatus codes."""

    PENDING, ACTIVE, PREEMPTED, SUCCEEDED, ABORTED, REJECTED, PREEMPTING, RECALLING, RECALLED, LOST = range(10)


class ROS2:
    """action_msgs/GoalStatus codes."""

    UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)


_ROS1_NAMES = ("PENDING", "ACTIVE", "PREEMPTED", "SUCCEEDED", "ABORTED", "REJECTED", "PREEMPTING", "RECALLING",
               "RECALLED", "LOST")
_ROS2_NAMES = ("UNKNOWN", "ACCEPTED", "EXECUTING", "CANCELING", "SUCCEEDED", "CANCELED", "ABORTED")

#: ROS 1 status -> ROS 2 status. ROS 2 has no REJECTED status (a goal is rejected in the goal response, before it
#: has one) nor LOST: both end a goal the helper already accepted as ABORTED.
_TO_ROS2 = {ROS1.PENDING: ROS2.ACCEPTED, ROS1.ACTIVE: ROS2.EXECUTING, ROS1.PREEMPTED: ROS2.CANCELED,
            ROS1.SUCCEEDED: ROS2.SUCCEEDED, ROS1.ABORTED: ROS2.ABORTED, ROS1.REJECTED: ROS2.ABORTED,
            ROS1.PREEMPTING: ROS2.CANCELING, ROS1.RECALLING: ROS2.CANCELING, ROS1.RECALLED: ROS2.CANCELED,
            ROS1.LOST: ROS2.ABORTED}
#: ROS 2 status -> ROS 1 status (UNKNOWN: the server does not know the goal, ROS 1's LOST)
_TO_ROS1 = {ROS2.UNKNOWN: ROS1.LOST, ROS2.ACCEPTED: ROS1.PENDING, ROS2.EXECUTING: ROS1.ACTIVE,
            ROS2.CANCELING: ROS1.PREEMPTING, ROS2.SUCCEEDED: ROS1.SUCCEEDED, ROS2.CANCELED: ROS1.PREEMPTED,
            ROS2.ABORTED: ROS1.ABORTED}


def ros1_to_ros2_status(status: int) -> int:
    """An actionlib_msgs/GoalStatus code as the action_msgs/GoalStatus code ROS 2 clients see."""
    return _TO_ROS2.get(status, ROS2.ABORTED)


def ros2_to_ros1_status(status: int) -> int:
    """An action_msgs/GoalStatus code as the actionlib_msgs/GoalStatus code ROS 1 clients see."""
    return _TO_ROS1.get(status, ROS1.LOST)


def status_name(status: int, side: str) -> str:
    """``status_name(3, "ROS 1")`` -> ``'SUCCEEDED'``."""
    names = _ROS1_NAMES if side == "ROS 1" else _ROS2_NAMES
    return names[status] if 0 <= status < len(names) else f"status {status}"


def check_action_class(action_class: Any) -> None:
    """TypeError in words unless ``action_class`` is a ROS 1 action class (``FibonacciAction``, what actionlib
    takes), not its goal or its ActionGoal."""
    slots = getattr(action_class, "__slots__", None)
    ok = (isinstance(action_class, type) and isinstance(getattr(action_class, "_type", None), str)
          and isinstance(slots, (list, tuple))
          and {"action_goal", "action_result", "action_feedback"} <= set(slots))
    if not ok:
        got = getattr(action_class, "_type", None) or repr(action_class)
        raise TypeError(f"action_class must be a ROS 1 action class as actionlib takes it (e.g. "
                        f"actionlib_tutorials.msg.FibonacciAction, with action_goal, action_result and "
                        f"action_feedback), got {got}")


def ros2_action_type(ros_type: str) -> str:
    """``test_msgs/FibonacciAction`` -> ``test_msgs/action/Fibonacci``."""
    pkg, _, name = ros_type.partition("/")
    if name.endswith("Action"):
        name = name[: -len("Action")]
    return f"{pkg}/action/{name}"


@dataclass(frozen=True)
class ActionMapping:
    """One action class's ROS 2 form and codecs (``encode_goal(msg) -> bytes`` etc.)."""

    ros_type: str
    ros2_type: str
    action_class: Any
    goal_class: Any
    result_class: Any
    feedback_class: Any
    encode_goal: Callable[[Any], bytes]
    decode_goal: Callable[[bytes], Any]
    encode_result: Callable[[Any], bytes]
    decode_result: Callable[[bytes], Any]
    encode_feedback: Callable[[Any], bytes]
    decode_feedback: Callable[[bytes], Any]


_cache: Dict[Any, ActionMapping] = {}
_lock = threading.Lock()


def action_mapping(action_class: Any, ros2_type: Optional[str] = None) -> ActionMapping:
    """The mapping of a ROS 1 action class (cached); ``ros2_type`` (``pkg/action/Name``) overrides the name rule.
    TypeMappingError names the type when a part cannot map."""
    check_action_class(action_class)
    if ros2_type is not None and ros2_type.count("/") != 2:
        raise ValueError(f"ros2_type must read pkg/action/Name, got {ros2_type!r}")
    with _lock:
        key = (action_class, ros2_type)
        found = _cache.get(key)
        if found is not None:
            return found
        spec = action_class()
        parts = {"goal": type(spec.action_goal.goal), "result": type(spec.action_result.result),
                 "feedback": type(spec.action_feedback.feedback)}
        # parts built at run time are not in roslib's message search path: make them known to the DDS mapping
        register_message_classes({cls._type: cls for cls in parts.values()})
        try:
            codecs = {part: _codec(cls) for part, cls in parts.items()}
        except TypeMappingError:
            raise
        except Exception as exc:
            raise TypeMappingError(f"cannot map the action type {action_class._type} to ROS 2: {exc}") from exc
        found = _cache[key] = ActionMapping(
            action_class._type, ros2_type or ros2_action_type(action_class._type), action_class,
            parts["goal"], parts["result"], parts["feedback"],
            codecs["goal"][0], codecs["goal"][1], codecs["result"][0], codecs["result"][1],
            codecs["feedback"][0], codecs["feedback"][1])
        return found
