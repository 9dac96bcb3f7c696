"""ROS 2 visibility on demand (``MICROS_RT_ROS2=auto``, the default): a node makes DDS entities for its topics
once something other than micros_rt is on its DDS domain (an rclpy node, the ``ros2`` CLI's daemon, any DDS
program), not before.

One node per host (network namespace), Unix user and DDS domain watches the domain for all of them: the one
that holds the lock file :attr:`Ros2Watch.lock_path` (``flock``; the kernel lets it go when the process dies, and
the next node to try takes over). The watcher starts its process's participant, with no topics, and reads the
participants it discovers (:mod:`micros_rt.transports.dds.discovery`). micros_rt participants say so in their user data
(:data:`PARTICIPANT_USER_DATA`); any other participant alive means ROS 2 is there, and the watcher creates the
marker file :attr:`Ros2Watch.marker` (the foreign participants' GUIDs in it) and removes it once they are gone.

While ROS 2 is there, the watcher is also the host's one DDS presence for ROS 2's graph
(:mod:`.host_gateway`): it stands in for the nodes no ROS 2 endpoint exchanges data with, and names in the
*visible* file (:func:`gateway_paths`) the nodes that one does; only those make their DDS writers and readers,
each on its next housekeeping tick, and stay so.

What it costs a robot with no ROS 2 node: one participant (the watcher's) instead of one per node; each other
node one ``stat`` and one non-blocking ``flock`` per tick, and a description file written when its topics change.
"""

from __future__ import annotations

import errno
import fcntl
import os
import tempfile
import time
from typing import Callable, FrozenSet, List, Optional, Set, Tuple

from ...exceptions import TransportError
from ...log import nonblocking_logger
from .discovery import Discovery
from .host_gateway import (EndpointDescription, HostGateway, named_visible, prune_descriptions, read_visible,
                           remove_description, write_description)
from .participant import HELPER_ENCLAVE, PARTICIPANT_USER_DATA, DDSParticipant

__all__ = ["PARTICIPANT_USER_DATA", "Ros2Watch", "gateway_paths", "is_micros_rt_participant", "read_visible",
           "watch_paths", "watcher_pid"]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: How long a new watcher keeps a marker it found before it may remove it: the foreign participants already on
#: the domain announce themselves again within their SPDP interval (Fast DDS: 3 s; Cyclone: a few seconds)
TAKEOVER_GRACE = 10.0


_HELPER_USER_DATA = f"enclave={HELPER_ENCLAVE};".encode()


def is_micros_rt_participant(user_data: Optional[bytes]) -> bool:
    """Whether a participant's user data is micros_rt's: a node's (:data:`PARTICIPANT_USER_DATA`) or one of its rclpy
    helpers' (:data:`HELPER_ENCLAVE`), which must not make the host's nodes ROS 2-visible by themselves.

    >>> is_micros_rt_participant(b"enclave=/micros_rt;"), is_micros_rt_participant(b"enclave=/;")
    (True, False)
    """
    data = bytes(user_data or b"")
    return b"micros_rt=1;" in data or data.startswith(_HELPER_USER_DATA)


def _netns() -> str:
    try:
        return str(os.stat("/proc/self/ns/net").st_ino)
    except OSError:
        return "host"


def _stem(domain: int) -> str:
    base = "/dev/shm" if os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()
    return os.path.join(base, f"micros_rt_ros2_u{os.getuid()}_n{_netns()}_d{domain}")


def watch_paths(domain: int) -> tuple[str, str]:
    """The lock file and the marker of this host (network namespace), user and DDS ``domain``."""
    stem = _stem(domain)
    return stem + ".lock", stem + ".seen"


def gateway_paths(domain: int) -> Tuple[str, str]:
    """The prefix of the nodes' description files and the *visible* file of the host's gateway
    (:mod:`.host_gateway`)."""
    stem = _stem(domain)
    return stem + ".node", stem + ".visible"


def watcher_pid(lock_path: str) -> Optional[int]:
    """The process holding ``lock_path`` (the watcher), from /proc/locks; None when nobody holds it."""
    try:
        st = os.stat(lock_path)
        with open("/proc/locks") as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    for line in lines:  # "1: FLOCK  ADVISORY  WRITE 4242 00:1a:1234 0 EOF"
        parts = line.split()
        if len(parts) >= 6 and parts[1] == "FLOCK":
            try:
                dev_major, dev_minor, inode = parts[5].split(":")
                if int(inode) == st.st_ino and os.makedev(int(dev_major, 16), int(dev_minor, 16)) == st.st_dev:
                    return int(parts[4])
            except ValueError:
                continue
    return None


class Ros2Watch:
    """One node's part in watching its DDS domain for ROS 2 (see the module's text)."""

    def __init__(self, domain: int, participant: Callable[[], Optional[DDSParticipant]]) -> None:
        self.domain = domain
        self.lock_path, self.marker = watch_paths(domain)
        self.nodes_prefix, self.visible_path = gateway_paths(domain)
        self._participant = participant
        self.gateway: Optional[HostGateway] = None
        self._visible_stat: Optional[Tuple[int, int, int]] = None
        self._named = False
        self._described: Optional[List[EndpointDescription]] = None
        self._fd: Optional[int] = None
        self._reader: Optional[Discovery] = None
        self._since = 0.0              # when this node became the watcher
        self._foreign: FrozenSet[str] = frozenset()
        self._helpers: Set[str] = set()  # micros_rt's own rclpy helpers seen (said once each)
        self.failed = False            # the watcher's participant could not start: said once, not tried again

    @property
    def watching(self) -> bool:
        return self._reader is not None

    def poll(self) -> bool:
        """True once the host's gateway named this node: a ROS 2 endpoint exchanges data with it (a cheap call:
        a ``stat`` of the visible file, read when it changed)."""
        if self._reader is None and not self.failed and self._take_lock():
            self._start_watching()
        if self._reader is not None:
            self._look()
        if not self._named:
            try:
                st = os.stat(self.visible_path)
                now: Optional[Tuple[int, int, int]] = (st.st_ino, st.st_mtime_ns, st.st_size)  # a new file each write
            except OSError:
                now = None
            if now is not None and now != self._visible_stat:
                self._named = named_visible(self.visible_path, self._node)
            self._visible_stat = now
        return self._named

    _node = ""

    def describe(self, node: str, endpoints: List[EndpointDescription]) -> None:
        """Tell the host's gateway this node's endpoints (written only when they changed; not once it is visible
        itself, when its own participant announces them)."""
        self._node = node
        if self._named:
            if self._described is not None:
                remove_description(self.nodes_prefix)
                self._described = None
            return
        if endpoints == self._described:
            return
        try:
            write_description(self.nodes_prefix, node, endpoints)
            self._described = list(endpoints)
        except OSError as exc:
            self._described = list(endpoints)  # said once per change, not per tick
            _log.warning("micros_rt: cannot describe this node's topics to the host's ROS 2 gateway (%s): ROS 2 "
                         "tools will not list them until a ROS 2 node uses one", exc)

    def foreign(self) -> FrozenSet[str]:
        """GUIDs of the participants that are not micros_rt's, as this watcher saw them last (empty elsewhere)."""
        return self._foreign

    def _take_lock(self) -> bool:
        try:
            if self._fd is None:
                self._fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o600)
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                self.failed = True  # another user's file, a read-only /dev/shm: this node never watches
                _log.warning("micros_rt: cannot take part in watching DDS domain %d for ROS 2 nodes (%s: %s); "
                             "this node's topics become ROS 2 topics only when another micros_rt node of this "
                             "host sees ROS 2, or with MICROS_RT_ROS2=on", self.domain, self.lock_path, exc)
            return False

    def _start_watching(self) -> None:
        participant = self._participant()
        if participant is None:
            self.failed = True  # DDS cannot start here: the participant said why, once
            self._release()
            return
        try:
            self._reader = Discovery(participant.dp, kinds=("participants:followed",))
        except TransportError as exc:
            self.failed = True
            self._release()
            if participant.closed:  # the process is ending: it took the lock of a watcher that ended first
                return
            _log.warning("micros_rt: cannot watch DDS domain %d for ROS 2 nodes (%s)", self.domain, exc)
            return
        self._since = time.monotonic()
        prune_descriptions(self.nodes_prefix)  # of nodes killed since the last watcher started
        _log.info("micros_rt: this node watches DDS domain %d for ROS 2 nodes on this host (%s)", self.domain,
                  self.lock_path)

    def _look(self) -> None:
        reader = self._reader
        if reader is None:
            return
        foreign = set()
        for p in reader.followed_participants():
            user_data = p.user_data
            if not is_micros_rt_participant(user_data):
                foreign.add(p.guid)
            elif bytes(user_data or b"").startswith(_HELPER_USER_DATA) and p.guid not in self._helpers:
                self._helpers.add(p.guid)
                _log.info("micros_rt: a micros_rt ROS 2 helper joined DDS domain %d (%s); it is not a ROS 2 node, "
                          "and this host's topics stay off DDS for it", self.domain, p.guid)
        if foreign != self._foreign:
            if foreign - self._foreign:
                _log.info("micros_rt: %d DDS participant(s) that are not micros_rt on domain %d (ROS 2 nodes or "
                          "tools): this host's micros_rt nodes are announced to ROS 2, and make their topics ROS 2 "
                          "topics once a ROS 2 node uses one", len(foreign),
                          self.domain)
            self._foreign = frozenset(foreign)
        if foreign:
            self._write_marker(foreign)
            self._serve(self._foreign)
        elif time.monotonic() - self._since > TAKEOVER_GRACE:
            self._remove_marker()
            self._close_gateway()

    def _serve(self, foreign: FrozenSet[str]) -> None:
        """ROS 2 is here: this watcher is the host's presence in its graph (:mod:`.host_gateway`)."""
        if self.gateway is None:
            participant = self._participant()
            if participant is None:
                return
            try:
                self.gateway = HostGateway(participant, self.nodes_prefix, self.visible_path)
            except Exception as exc:  # Cyclone refused an entity: nodes stay off ROS 2's graph until next tick
                _log.warning("micros_rt: cannot start the host's ROS 2 gateway on domain %d (%s); will retry",
                             self.domain, exc)
                return
            _log.info("micros_rt: this node is the host's ROS 2 gateway on DDS domain %d: it announces this host's "
                      "micros_rt nodes to ROS 2", self.domain)
        self.gateway.update(foreign)

    def _close_gateway(self) -> None:
        gateway, self.gateway = self.gateway, None
        if gateway is not None:
            gateway.close()

    def _write_marker(self, foreign: "set[str]") -> None:
        text = "".join(sorted(g + "\n" for g in foreign))
        try:
            with open(self.marker, "r") as f:
                if f.read() == text:
                    return
        except OSError:
            pass
        tmp = f"{self.marker}.{os.getpid()}"
        try:
            with open(tmp, "w") as f:
                f.write(text)
            os.replace(tmp, self.marker)  # readers see the whole file or none
        except OSError as exc:
            _log.warning("micros_rt: cannot write %s (%s): other micros_rt nodes of this host will not make their "
                         "topics ROS 2 topics; MICROS_RT_ROS2=on does it without the watcher", self.marker, exc)

    def _remove_marker(self) -> None:
        try:
            os.unlink(self.marker)
        except FileNotFoundError:
            pass
        except OSError as exc:
            _log.debug("micros_rt: removing %s: %s", self.marker, exc)

    def _release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # the lock goes with the descriptor
            self._fd = None

    def close(self) -> None:
        """Stop watching (at shutdown; the next node to try takes over). The marker stays for the next watcher."""
        self._close_gateway()
        if self._described is not None:
            remove_description(self.nodes_prefix)
            self._described = None
        self._reader = None  # its readers are deleted with the participant
        self._release()
