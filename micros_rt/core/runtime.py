"""Process-wide state of the micros_rt node (one per process, as in rospy): the endpoint registries,
the DDS back end, the graph id and the YAML profile."""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Optional

import rospy

from ..cyclone import import_cyclonedds
from .registry import EndpointRegistry
from ..transports.dds.participant import get_participant
from .. import settings
from ..exceptions import MicrosRtError, NodeNotInitializedError, SettingError
from ..qos import QoSProfile
from ..log import nonblocking_logger

if TYPE_CHECKING:
    from .publication import _Publication
    from .subscription import _Subscription
    from ..transports.dds.backend import DDSBackend
    from ..transports.pacing import LinkPacer
    from ..transports.dds.watch import Ros2Watch

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
    dds: "Optional[DDSBackend]" = None
    dds_start: Optional[threading.Thread] = None
    #: TCP pacing across the profile's links of limited bandwidth (None: the profile names none)
    pacer: "Optional[LinkPacer]" = None
    #: ``auto`` ROS 2 visibility: this node's part in watching the domain, and whether ROS 2 has been seen
    ros2_watch: "Optional[Ros2Watch]" = None
    ros2_seen: bool = False


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


ON, OFF, AUTO = "on", "off", "auto"
_warned_modes: set[str] = set()


def ros2_mode(profile: Optional[QoSProfile] = None) -> str:
    """How this node's topics become ROS 2 topics: ``MICROS_RT_ROS2`` (on/off/auto), else the profile's ``ros2:``
    (true: on, false: off), else auto.

    - on: a DDS participant, writers and readers made with each topic, as an rclpy node's.
    - auto: as off until something other than micros_rt is on the DDS domain (a ROS 2 node or tool, seen by the
      host's watcher, :mod:`micros_rt.transports.dds.watch`), then as on.
    - off: DDS entities only when a peer needs them (a micros_rt node on another host, a relay)."""
    try:
        mode = settings.ROS2.get()
    except SettingError as exc:  # init_node refuses it; said once here (asked per topic and per housekeeping tick)
        if str(exc) not in _warned_modes:
            _warned_modes.add(str(exc))
            _log.warning("micros_rt: %s; auto it is", exc)
        return AUTO
    if mode is None and profile is not None and profile.ros2 is not None:
        return ON if profile.ros2 else OFF
    return mode or AUTO


def ros2_visible(profile: Optional[QoSProfile] = None) -> bool:
    """Whether this node's topics are ROS 2 topics now (:func:`ros2_mode`; auto: once ROS 2 has been seen).
    Not visible, a node makes DDS entities only when a peer needs them: a robot with no ROS 2 node pays
    nothing for DDS but the host watcher's participant."""
    mode = ros2_mode(profile)
    return mode == ON or (mode == AUTO and _node.ros2_seen)


def note_ros2_at_start(profile: Optional[QoSProfile]) -> None:
    """With ``auto`` visibility, at ``init_node``: a node started while ROS 2 is there is visible from its first
    topic (the host's watcher left its marker); becoming the watcher waits for the first housekeeping tick."""
    if ros2_mode(profile) != AUTO or settings.DISABLE_DDS.get():
        return
    from ..transports.dds.participant import domain_id_from_env
    from ..transports.dds.watch import watch_paths

    try:
        seen = os.path.exists(watch_paths(domain_id_from_env())[1])
    except MicrosRtError:
        return
    if seen:
        with _node.lock:
            _node.ros2_seen = True


def watch_ros2() -> bool:
    """With ``auto`` visibility, a housekeeping tick: take part in watching the DDS domain for ROS 2; True once,
    on the tick ROS 2 is first seen (the caller opens the topics' DDS sides)."""
    if (settings.DISABLE_DDS.get() or ros2_mode(_node.profile) != AUTO
            or rospy.is_shutdown()):
        return False
    watch = _node.ros2_watch
    if watch is None:
        from ..transports.dds.participant import domain_id_from_env
        from ..transports.dds.watch import Ros2Watch

        try:
            watch = _node.ros2_watch = Ros2Watch(domain_id_from_env(), get_participant)
        except MicrosRtError:
            return False  # a bad ROS_DOMAIN_ID: the first DDS use says so
    seen = watch.poll()
    if seen and not _node.ros2_seen:
        with _node.lock:
            _node.ros2_seen = True
        return True
    return False


def _require_node() -> None:
    """The node is ready for a topic: initialised, and the DDS import that ``init_node`` started finished."""
    if not _node.initialized:
        raise NodeNotInitializedError("call micros_rt.init_node(name) before advertising or subscribing")
    # cyclonedds's modules import each other in a cycle: a second thread importing them meanwhile meets one
    # half-initialised ("cannot import name 'DcpsEndpoint' from partially initialized module
    # 'cyclonedds.builtin_types'", once in 180 benchmark phases: a subscribe right after init_node)
    wait_dds_started()


def start_dds_early(profile: Optional[QoSProfile] = None) -> None:
    """Import the DDS back end on a background thread while rospy registers the node with the master.

    Importing cyclonedds and micros_rt's DDS modules takes 80-200 ms of a node's start, and the node's
    first ``advertise`` or ``subscribe`` waited for it; ``init_node`` spends a good part of that waiting
    on the master's answers. The participant itself (~3 ms) is still created by the first topic, after
    rospy's logging is set up, so a DDS that cannot start is reported as before. rospy's ``init_node``
    imports only configparser and encodings.idna meanwhile, and the first topic waits for this thread
    (:func:`_require_node`), so no two threads import cyclonedds at once."""
    if settings.DISABLE_DDS.get() or not ros2_visible(profile):
        return  # no DDS, or DDS only when a peer needs it: no import now

    def start() -> None:
        try:
            import_cyclonedds()
            from ..transports.dds import backend  # noqa: F401
        except Exception:  # the first topic imports them again and reports what is wrong, in words
            pass

    thread = threading.Thread(target=start, name="micros_rt DDS import", daemon=True)
    with _node.lock:
        _node.dds_start = thread
    thread.start()


def wait_dds_started(timeout: float = 10.0) -> None:
    """Let the early import finish (before the participant is closed, at shutdown)."""
    thread = _node.dds_start
    if thread is not None and thread is not threading.current_thread():
        thread.join(timeout)
        if not thread.is_alive():
            _node.dds_start = None


def dds_backend() -> "Optional[DDSBackend]":
    """The DDS back end of this process (created with the participant), or None without DDS."""
    wait_dds_started()  # a program calling this before any topic (the relay) must not import cyclonedds beside it
    participant = get_participant()
    if participant is None:
        return None
    with _node.lock:
        if _node.dds is None or _node.dds.participant is not participant:
            from ..transports.dds.backend import DDSBackend

            _node.dds = DDSBackend(participant, str(rospy.get_caller_id()))
            if _node.profile is not None:
                from ..qos.links import send_buffer_below_high

                _node.dds.send_buffer_below_high = send_buffer_below_high(_node.profile.links)
        return _node.dds
