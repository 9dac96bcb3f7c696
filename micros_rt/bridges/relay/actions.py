"""Actions in the relay's ``ros2:`` section: a ROS 1 (actionlib) action server offered to ROS 2 action clients
(export), a ROS 2 action server offered to ROS 1 (actionlib) clients (import).

Both stand on the node API (:meth:`micros_rt.NodeHandle.offer_action_to_ros2`,
:meth:`micros_rt.NodeHandle.offer_ros2_action`, docs/actions.md); this module only finds the action and its type:

- **export**: an entry is a ROS 1 action when a node other than the relay publishes ``<name>/status`` and
  ``<name>/feedback`` has an ``*ActionFeedback`` type in the master (``pkg/FooActionFeedback`` -> ``pkg/FooAction``;
  ROS 2 type ``pkg/action/Foo``);
- **import**: an entry is a ROS 2 action when DDS discovery has a ROS 2 server's reader of
  ``rq/<name>/_action/send_goalRequest`` (``pkg::action::dds_::Foo_SendGoal_Request_`` -> ``pkg/action/Foo``).

The ROS 1 class (``pkg/FooAction``) is the installed one, else it is built at run time from the ROS 2 definition
(``share/<pkg>/action/Foo.action`` of the ROS 2 installation the helper runs in, which must have the type anyway)
as actionlib's genaction expands an ``.action`` file (:mod:`micros_rt.ros2_types`: ROS 2's field syntax mapped
back to ROS 1's, nested ROS 2-only types rewritten in turn).
On export the classes are checked against the md5 the ROS 1 server's ``feedback`` and ``result`` publishers
announce.
"""

from __future__ import annotations

import re
from typing import Any, Dict, Optional, Tuple

from .config import Ros2Entry
from .msgtypes import TypeLearningError, publisher_header

__all__ = ["ActionIn", "ActionOut", "action_class", "check_against_server", "ros1_action_type", "ros2_action_type",
           "ros2_action_type_of", "send_goal_topic"]

_SEND_GOAL = re.compile(r"^(\w+)::action::dds_::(\w+)_SendGoal_Request_$")


def ros2_action_type_of(dds_type: str) -> Optional[str]:
    """A send_goal request's DDS type to the ROS 2 action type: ``test_msgs::action::dds_::Fibonacci_SendGoal_Request_``
    -> ``test_msgs/action/Fibonacci``; None for anything else."""
    found = _SEND_GOAL.match(dds_type)
    return f"{found.group(1)}/action/{found.group(2)}" if found else None


def ros2_action_type(ros1_type: str) -> str:
    """``test_msgs/FibonacciAction`` -> ``test_msgs/action/Fibonacci``."""
    pkg, _, name = ros1_type.partition("/")
    return f"{pkg}/action/{name[: -len('Action')] if name.endswith('Action') else name}"


def ros1_action_type(ros2_type: str) -> str:
    """``test_msgs/action/Fibonacci`` -> ``test_msgs/FibonacciAction``."""
    pkg, _, name = ros2_type.rpartition("/")
    return f"{pkg.split('/')[0]}/{name}Action"


def send_goal_topic(name: str) -> str:
    """The DDS topic a ROS 2 action server of ``name`` reads goals from."""
    return "rq/" + name.lstrip("/") + "/_action/send_goalRequest"


def action_class(ros2_type: str, helper_python: str) -> Tuple[Any, str]:
    """The ROS 1 action class of ROS 2 action type ``ros2_type`` and where it came from (``installed`` or
    ``built from <file>``, :func:`micros_rt.ros2_action_class`); :class:`TypeLearningError` in words when neither
    can be had."""
    from micros_rt.ros2_types import Ros2TypeError, ros2_action_class

    try:
        return ros2_action_class(ros2_type, python=helper_python)
    except (Ros2TypeError, ValueError) as exc:
        raise TypeLearningError(str(exc)) from None


def check_against_server(cls: Any, name: str, master: Any, caller_id: str, skip: Tuple[str, ...]) -> None:
    """TypeLearningError unless the ROS 1 server's ``feedback`` and ``result`` publishers announce the md5 of
    ``cls``'s parts (a server with another definition of the type)."""
    spec = cls()
    for topic, part in (("feedback", spec.action_feedback), ("result", spec.action_result)):
        try:
            header = publisher_header(master, f"{name}/{topic}", caller_id=caller_id, skip=skip)
        except TypeLearningError:
            continue   # not asked (the server busy or gone): rospy still refuses a wrong md5 at the connection
        md5 = header.get("md5sum", "")
        if md5 and md5 != type(part)._md5sum:
            raise TypeLearningError(f"its server's {name}/{topic} has md5 {md5}, the ROS 2 type's mapping gives "
                                    f"{type(part)._md5sum} for {type(part)._type}: the two definitions differ")


class ActionOut:
    """A ROS 1 action server offered to ROS 2 action clients (``offer_action_to_ros2``)."""

    kind = "action"

    def __init__(self, nh: Any, entry: Ros2Entry, cls: Any, source: str) -> None:
        self.entry = entry
        self.source = source
        self.handle = nh.offer_action_to_ros2(entry.name, cls, accept_timeout=entry.timeout)

    def refresh(self, side: Any, state: Any) -> None:
        pass

    def stats(self) -> Dict[str, Any]:
        h = self.handle
        return {"direction": "export", "kind": "action", "name": self.entry.name, "as": self.entry.ros2_name,
                "type": h.mapping.ros_type, "ros2_type": h.ros2_type, "type_source": self.source,
                "server_connected": h.server_present(), **h.statistics()}

    def close(self) -> None:
        self.handle.shutdown()


class ActionIn:
    """A ROS 2 action server offered to ROS 1 (actionlib) clients (``offer_ros2_action``)."""

    kind = "action"

    def __init__(self, nh: Any, entry: Ros2Entry, cls: Any, ros2_type: str, source: str) -> None:
        self.entry = entry
        self.source = source
        self.handle = nh.offer_ros2_action(entry.name, cls, ros2_type=ros2_type, accept_timeout=entry.timeout)

    def refresh(self, side: Any, state: Any) -> None:
        pass

    def stats(self) -> Dict[str, Any]:
        h = self.handle
        return {"direction": "import", "kind": "action", "name": self.entry.name, "as": self.entry.ros1_name,
                "type": h.mapping.ros_type, "ros2_type": h.ros2_type, "type_source": self.source, **h.statistics()}

    def close(self) -> None:
        self.handle.shutdown()
