"""Process-wide state of the micros_rt node (one per process, as in rospy)."""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Dict, Optional

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
