"""Process-wide state of the micros_rt node (one per process, as in rospy): the endpoint registries, the graph id,
the YAML profile, and what the node does before a topic (wait for the DDS start-up it began,
:mod:`micros_rt.transports.dds.process`, which holds the process's DDS). It names no transport."""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Dict, Optional

import rospy

from .registry import EndpointRegistry
from ..exceptions import NodeNotInitializedError
from ..qos import QoSProfile
from ..log import nonblocking_logger

if TYPE_CHECKING:
    from .publication import _Publication
    from .subscription import _Subscription
    from ..transports.pacing import LinkPacer

_log = nonblocking_logger("rosout.micros_rt")  # rospy prints it and sends it to /rosout


@dataclass
class _NodeState:
    initialized: bool = False
    graph: str = ""
    profile: Optional[QoSProfile] = None
    publications: "EndpointRegistry[_Publication]" = field(default_factory=lambda: EndpointRegistry("publication"))
    subscriptions: "EndpointRegistry[_Subscription]" = field(
        default_factory=lambda: EndpointRegistry("subscription"))
    lock: threading.RLock = field(default_factory=threading.RLock)
    #: TCP pacing across the profile's links of limited bandwidth (None: the profile names none)
    pacer: "Optional[LinkPacer]" = None
    #: what a topic waits for first (the node sets it: the DDS start-up it began)
    before_topic: Callable[[], None] = lambda: None
    #: the process's DDS back end, for ``microsRtInfo`` (domain, participant; None: none)
    dds_info: Callable[[], Optional[Dict[str, Any]]] = lambda: None


_node = _NodeState()


def _graph_id() -> str:
    # The master's run_id names this ROS graph; the master URI makes it unique
    # even when a run_id is reused. Readers drop micros_rt writers of other graphs.
    try:
        run_id = str(rospy.get_param("/run_id"))
    except (KeyError, OSError, rospy.ROSException):
        run_id = "norunid"
    uri = os.environ.get("ROS_MASTER_URI", "")
    return f"{run_id}@{uri}".replace(";", "_").replace("=", "_")[:200]


def _require_node() -> None:
    """The node is ready for a topic: initialised, and what it began for topics (the DDS start-up) finished."""
    if not _node.initialized:
        raise NodeNotInitializedError("call micros_rt.init_node(name) before advertising or subscribing")
    _node.before_topic()
