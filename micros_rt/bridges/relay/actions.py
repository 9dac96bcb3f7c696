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
as actionlib's genaction expands an ``.action`` file: ROS 2's field syntax mapped back to ROS 1's (bounds and
default values dropped, ``builtin_interfaces/Time`` as ``time``), nested types taken from installed ROS 1 packages.
On export the classes are checked against the md5 the ROS 1 server's ``feedback`` and ``result`` publishers
announce.
"""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

from .config import Ros2Entry
from .msgtypes import TypeLearningError, class_from_definition, installed_class, publisher_header

__all__ = ["ActionIn", "ActionOut", "action_class", "check_against_server", "ros1_action_type", "ros2_action_type",
           "ros2_action_type_of", "send_goal_topic"]

_SEND_GOAL = re.compile(r"^(\w+)::action::dds_::(\w+)_SendGoal_Request_$")
_SEP = "=" * 80 + "\n"
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
               "int64", "uint64", "string"}
_FIELD = re.compile(r"^(?P<type>[A-Za-z][\w/]*)(?P<bound><=\d+)?(?P<array>\[(?:<=)?\d*\])?\s+(?P<name>\w+)"
                    r"(?P<rest>.*)$")
_built: Dict[Tuple[str, str], Any] = {}
_lock = threading.Lock()


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


def _sections(cls: Any) -> Dict[str, str]:
    """An installed class's full text as {type: its own text}, itself and every type it uses."""
    parts = str(cls._full_text).split(_SEP)
    out = {cls._type: parts[0]}
    for part in parts[1:]:
        head, _, body = part.partition("\n")
        if head.startswith("MSG: "):
            out[head[5:].strip()] = body
    return out


def _ros1_field_type(base: str, pkg: str, deps: Dict[str, str], where: str) -> str:
    if base in _PRIMITIVES:
        return base
    if base == "wstring":
        raise TypeLearningError(f"{where}: ROS 1 has no wstring")
    full = base if "/" in base else f"{pkg}/{base}"
    if full == "builtin_interfaces/Time":
        return "time"
    if full == "builtin_interfaces/Duration":
        return "duration"
    cls = installed_class(full)
    if cls is None:
        raise TypeLearningError(f"{where}: the ROS 1 message {full} is not installed on this host")
    deps.update(_sections(cls))
    return full


def _ros1_text(ros2_text: str, pkg: str, deps: Dict[str, str], where: str) -> str:
    """One part of a ROS 2 ``.action`` file as a ROS 1 message definition."""
    lines: List[str] = []
    for raw in ros2_text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        found = _FIELD.match(line)
        if found is None:
            raise TypeLearningError(f"{where}: cannot read the line {line!r}")
        ftype = _ros1_field_type(found["type"], pkg, deps, where)
        array = found["array"] or ""
        if array.startswith("[<="):
            array = "[]"   # a bounded sequence: ROS 1 has unbounded arrays only
        rest = found["rest"].strip()
        if rest.startswith("="):   # a constant: kept (a string constant's value is the rest of the line)
            value = rest[1:].strip() if ftype == "string" else rest[1:].split("#")[0].strip()
            lines.append(f"{ftype}{array} {found['name']}={value}")
        else:                       # a field; a default value (ROS 2 only) is dropped
            lines.append(f"{ftype}{array} {found['name']}")
    return "".join(f"{line}\n" for line in lines)


def _action_file(ros2_type: str, helper_python: str) -> Path:
    pkg, _, name = ros2_type.rpartition("/")
    pkg = pkg.split("/")[0]
    prefixes = [Path(helper_python).parent.parent]
    prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes:
        candidate = prefix / "share" / pkg / "action" / f"{name}.action"
        if candidate.is_file():
            return candidate
    raise TypeLearningError(f"the ROS 1 action type {pkg}/{name}Action is not installed on this host, and the "
                            f"ROS 2 definition {pkg}/action/{name}.action is in none of "
                            f"{', '.join(str(p / 'share') for p in prefixes)}")


def _built_from_ros2(ros2_type: str, helper_python: str) -> Any:
    from actionlib_msgs.msg import GoalID, GoalStatus  # type: ignore[import-untyped]
    from std_msgs.msg import Header

    path = _action_file(ros2_type, helper_python)
    pkg, name = ros2_type.split("/")[0], ros2_type.rpartition("/")[2]
    parts = re.split(r"^---\s*$", path.read_text(), flags=re.M)
    if len(parts) != 3:
        raise TypeLearningError(f"{path}: expected goal, result and feedback separated by '---'")
    deps: Dict[str, str] = {}
    texts = {part: _ros1_text(text, pkg, deps, f"{path} ({part.lower()})")
             for part, text in zip(("Goal", "Result", "Feedback"), parts)}
    deps.update({
        f"{pkg}/{name}ActionGoal": f"Header header\nactionlib_msgs/GoalID goal_id\n{name}Goal goal\n",
        f"{pkg}/{name}ActionResult": f"Header header\nactionlib_msgs/GoalStatus status\n{name}Result result\n",
        f"{pkg}/{name}ActionFeedback": f"Header header\nactionlib_msgs/GoalStatus status\n{name}Feedback feedback\n",
        **_sections(Header), **_sections(GoalID), **_sections(GoalStatus),
        **{f"{pkg}/{name}{part}": text for part, text in texts.items()},
    })
    core = f"{name}ActionGoal action_goal\n{name}ActionResult action_result\n{name}ActionFeedback action_feedback\n"
    definition = core + "".join(f"{_SEP}MSG: {t}\n{text}" for t, text in deps.items())
    return class_from_definition(f"{pkg}/{name}Action", "", definition)


def action_class(ros2_type: str, helper_python: str) -> Tuple[Any, str]:
    """The ROS 1 action class of ROS 2 action type ``ros2_type`` and where it came from (``installed`` or
    ``built from <file>``); :class:`TypeLearningError` in words when neither can be had."""
    ros1 = ros1_action_type(ros2_type)
    cls = installed_class(ros1)
    if cls is not None:
        return cls, "installed"
    with _lock:
        found = _built.get((ros2_type, helper_python))
        if found is None:
            found = _built[(ros2_type, helper_python)] = (_built_from_ros2(ros2_type, helper_python),
                                                          f"built from {_action_file(ros2_type, helper_python)}")
        return found


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
