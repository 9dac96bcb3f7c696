"""This process's DDS: whether its topics are ROS 2 topics (``MICROS_RT_ROS2`` / the profile's ``ros2:``: on, off,
auto), the early import of the DDS modules while rospy registers the node, the back end (made with the
participant), and the node's part in watching the domain for ROS 2 (``auto``). The node
(:mod:`micros_rt.node`) drives it; the core names none of it."""

from __future__ import annotations

import os
import threading
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional

from ... import settings
from ...cyclone import import_cyclonedds
from ...exceptions import MicrosRtError, SettingError
from ...log import nonblocking_logger
from .participant import get_participant

if TYPE_CHECKING:
    from .backend import DDSBackend
    from .host_gateway import EndpointDescription
    from .watch import Ros2Watch

__all__ = ["AUTO", "OFF", "ON", "backend", "close", "info", "ros2_mode", "ros2_on_domain", "ros2_visible",
           "start_early", "wait_started", "watch_ros2"]

_log = nonblocking_logger("rosout.micros_rt")

ON, OFF, AUTO = "on", "off", "auto"
_warned_modes: set[str] = set()


class _ProcessDDS:
    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.backend: "Optional[DDSBackend]" = None
        self.start: Optional[threading.Thread] = None
        #: ``auto`` ROS 2 visibility: this node's part in watching the domain, and whether ROS 2 has been seen
        self.watch: "Optional[Ros2Watch]" = None
        self.ros2_seen = False


_state = _ProcessDDS()


def _disabled() -> bool:
    return bool(settings.DISABLE_DDS.get())


def ros2_mode(profile: Any = None) -> str:
    """How this node's topics become ROS 2 topics: ``MICROS_RT_ROS2`` (on/off/auto), else the profile's ``ros2:``
    (true: on, false: off), else auto.

    - on: a DDS participant, writers and readers made with each topic, as an rclpy node's.
    - auto: as off; while something other than micros_rt is on the DDS domain (a ROS 2 node or tool, seen by the
      host's watcher, :mod:`micros_rt.transports.dds.watch`), the watcher announces the host's nodes to ROS 2, and
      a node becomes as on once a ROS 2 endpoint is on one of its topics (:mod:`.host_gateway`).
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
    return str(mode or AUTO)


def ros2_visible(profile: Any = None) -> bool:
    """Whether this node's topics are ROS 2 topics now (:func:`ros2_mode`; auto: once ROS 2 has been seen).
    Not visible, a node makes DDS entities only when a peer needs them: a robot with no ROS 2 node pays
    nothing for DDS but the host watcher's participant."""
    mode = ros2_mode(profile)
    return mode == ON or (mode == AUTO and _state.ros2_seen)


def ros2_on_domain(profile: Any = None) -> bool:
    """Whether a ROS 2 peer may be on this node's DDS domain now, for what only one needs: the rclpy helper of
    micros_rt's services and actions (:mod:`micros_rt.services.gateway`). ``auto``: once the host's watcher has
    seen something other than micros_rt on the domain (its marker file, one ``stat``) or this node is ROS
    2-visible; True whenever that cannot be known here (no watch possible: DDS disabled or failed, a bad domain id).
    ``on`` and ``off``: True (``off`` keeps the topics off DDS; services reach ROS 2 as before)."""
    if _disabled() or ros2_mode(profile) != AUTO or _state.ros2_seen:
        return True
    watch = _state.watch
    if watch is not None:
        if watch.failed:
            return True
        marker = watch.marker
    else:
        from .participant import domain_id_from_env
        from .watch import watch_paths

        try:
            marker = watch_paths(domain_id_from_env())[1]
        except MicrosRtError:
            return True
    return os.path.exists(marker)


def watch_ros2(profile: Any, node: str, endpoints: "Callable[[], List[EndpointDescription]]") -> bool:
    """With ``auto`` visibility, a housekeeping tick: tell the host's ROS 2 gateway this node's ``endpoints``, take
    part in watching the DDS domain for ROS 2; True once, on the tick the gateway first names this node (a ROS 2
    endpoint is on one of its topics: the caller opens the topics' DDS sides)."""
    if _disabled() or ros2_mode(profile) != AUTO:
        return False
    watch = _state.watch
    if watch is None:
        from .participant import domain_id_from_env
        from .watch import Ros2Watch

        try:
            watch = _state.watch = Ros2Watch(domain_id_from_env(), get_participant)
        except MicrosRtError:
            return False  # a bad ROS_DOMAIN_ID: the first DDS use says so
    watch.describe(node, endpoints())
    seen = watch.poll()  # the host's gateway named this node: a ROS 2 endpoint exchanges data with it
    if seen and not _state.ros2_seen:
        with _state.lock:
            _state.ros2_seen = True
        return True
    return False


def start_early(profile: Any = None) -> None:
    """Import the DDS back end on a background thread while rospy registers the node with the master.

    Importing cyclonedds and micros_rt's DDS modules takes 80-200 ms of a node's start, and the node's
    first ``advertise`` or ``subscribe`` waited for it; ``init_node`` spends a good part of that waiting
    on the master's answers. The participant itself (~3 ms) is still created by the first topic, after
    rospy's logging is set up, so a DDS that cannot start is reported as before. rospy's ``init_node``
    imports only configparser and encodings.idna meanwhile, and the first topic waits for this thread
    (:func:`wait_started`), so no two threads import cyclonedds at once."""
    if _disabled() or not ros2_visible(profile):
        return  # no DDS, or DDS only when a peer needs it: no import now

    def start() -> None:
        try:
            import_cyclonedds()
            from . import backend as _backend  # noqa: F401
        except Exception:  # the first topic imports them again and reports what is wrong, in words
            pass

    thread = threading.Thread(target=start, name="micros_rt DDS import", daemon=True)
    with _state.lock:
        _state.start = thread
    thread.start()


def wait_started(timeout: float = 10.0) -> None:
    """Let the early import finish (before a topic, and before the participant is closed at shutdown).

    cyclonedds's modules import each other in a cycle: a second thread importing them meanwhile meets one
    half-initialised ("cannot import name 'DcpsEndpoint' from partially initialized module
    'cyclonedds.builtin_types'", once in 180 benchmark phases: a subscribe right after init_node)."""
    thread = _state.start
    if thread is not None and thread is not threading.current_thread():
        thread.join(timeout)
        if not thread.is_alive():
            _state.start = None


def backend(caller_id: Callable[[], str], send_buffer_below_high: Callable[[], Optional[int]]) -> \
        "Optional[DDSBackend]":
    """The DDS back end of this process (created with the participant), or None without DDS."""
    wait_started()  # a program calling this before any topic (the relay) must not import cyclonedds beside it
    participant = get_participant()
    if participant is None:
        return None
    with _state.lock:
        if _state.backend is None or _state.backend.participant is not participant:
            from .backend import DDSBackend

            _state.backend = DDSBackend(participant, caller_id())
            below = send_buffer_below_high()
            if below is not None:
                _state.backend.send_buffer_below_high = below
        return _state.backend


def info() -> Optional[Dict[str, Any]]:
    """The domain and participant of this process's DDS back end (None: none)."""
    dds = _state.backend
    return None if dds is None else {"domain": dds.domain_id, "participant": dds.participant.guid}


def close() -> None:
    """At shutdown, after the topics: the watch (another node of the host takes it over at its next tick) and the
    back end."""
    wait_started()
    with _state.lock:
        dds, _state.backend = _state.backend, None
        watch, _state.watch = _state.watch, None
    if watch is not None:
        watch.close()
    if dds is not None:
        dds.close()
