"""Process-wide state of the micros_rt node (one per process, as in rospy)."""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, Optional

import rospy

from .dds.participant import DDSParticipant, get_participant
from .exceptions import NodeNotInitializedError
from .qos import QoSProfile

if TYPE_CHECKING:
    from ._publication import _Publication
    from ._subscription import _Subscription

_log = logging.getLogger("rosout.micros_rt")  # rospy prints it and sends it to /rosout


@dataclass
class _NodeState:
    initialized: bool = False
    graph: str = ""
    profile: Optional[QoSProfile] = None
    publications: Dict[str, "_Publication"] = field(default_factory=dict)
    subscriptions: Dict[str, "_Subscription"] = field(default_factory=dict)
    lock: threading.RLock = field(default_factory=threading.RLock)
    ros2_graph: Any = None  # Ros2GraphAnnouncer, created with the first DDS endpoint


_node = _NodeState()


def _graph_id() -> str:
    # The master's run_id names this ROS graph; the master URI makes it unique
    # even when a run_id is reused. Readers drop micros_rt writers of other graphs.
    try:
        run_id = str(rospy.get_param("/run_id"))
    except Exception:
        run_id = "norunid"
    uri = os.environ.get("ROS_MASTER_URI", "")
    return f"{run_id}@{uri}".replace(";", "_").replace("=", "_")


def _require_node() -> None:
    if not _node.initialized:
        raise NodeNotInitializedError("call micros_rt.init_node(name) before advertising or subscribing")


def _dds_participant() -> Optional[DDSParticipant]:
    return get_participant()


def _depth(queue_size: Optional[int]) -> int:
    return queue_size if queue_size and queue_size > 0 else 1000


def announce_to_ros2(*, add_reader: str = "", add_writer: str = "", remove: str = "") -> None:
    """Keep ROS 2's graph (``ros_discovery_info``) told which endpoints this node has.

    A courtesy to ROS 2 tools: failures are logged at debug level and change nothing else.
    """
    participant = get_participant()
    if participant is None or not _node.initialized:
        return
    with _node.lock:
        if _node.ros2_graph is None or _node.ros2_graph.participant is not participant:
            from .dds.ros2_graph import Ros2GraphAnnouncer

            try:
                _node.ros2_graph = Ros2GraphAnnouncer(participant, str(rospy.get_caller_id()))
            except Exception as exc:
                _log.debug("micros_rt: no ROS 2 graph announcement: %s", exc)
                return
        announcer = _node.ros2_graph
    announcer.update(add_reader=add_reader, add_writer=add_writer, remove=remove)
