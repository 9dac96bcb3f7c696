"""Every ``MICROS_RT_*`` environment variable micros_rt reads, in one table: its name, the values it takes, its
default and what it does (:data:`SETTINGS`; docs/troubleshooting.md#settings shows the same table, and a test
keeps the two alike). No other module of the package reads a ``MICROS_RT_*`` variable from the environment: each asks its
:class:`Setting` (``DISABLE_DDS.get()``, or ``.get(env)`` with a mapping of its own, as the tools and tests do).

A value is parsed where it is read, each time (a test or a tool may change the environment between two reads),
and a bad one is a :class:`~micros_rt.exceptions.SettingError` naming the variable, the value and what it takes.
:func:`micros_rt.init_node` checks them all first (:func:`check`), so a node with a mistyped setting stops at its
start, in words, rather than running in a mode nobody asked for.

>>> DISABLE_DDS.get({"MICROS_RT_DISABLE_DDS": "1"}), DISABLE_DDS.get({})
(True, False)
>>> SEND_BUFFER.get({"MICROS_RT_SEND_BUFFER": "16kB"})
16384
>>> LEASE_DURATION.get({"MICROS_RT_LEASE_DURATION": "soon"})
Traceback (most recent call last):
    ...
micros_rt.exceptions.SettingError: MICROS_RT_LEASE_DURATION='soon' is not a number of seconds; expected seconds, 0.5 to 3600 (unset: 15 s on a network interface; on loopback 5 s, or 1.5 s with MICROS_RT_DISABLE_SHM)
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Generic, List, Mapping, Optional, Tuple, TypeVar, Union

from .exceptions import SettingError

__all__ = ["DISABLE_DDS", "DISABLE_ROS2_SERVICES", "DISABLE_SHM", "LEASE_DURATION", "MALLOC_ARENA_MAX",
           "MALLOC_KEEP_LARGE", "MIN_SEND_BUFFER", "QOS_PROFILE", "RECEIVE_PRIORITY", "ROS2", "ROS2_PYTHON",
           "SEND_BUFFER", "SETTINGS", "Setting", "TYPE_CACHE", "check", "unknown"]

T = TypeVar("T")

_ON = ("1", "on", "true", "yes")
_OFF = ("0", "off", "false", "no")


@dataclass(frozen=True)
class Setting(Generic[T]):
    """One ``MICROS_RT_*`` variable: ``name``, the values it takes (``takes``, in words), its default (``default``,
    in words; ``unset`` is the value :meth:`get` returns then), what it does (``meaning``) and ``parse``, which
    turns the text into the value or raises ValueError saying what is wrong with it."""

    name: str
    takes: str
    default: str
    meaning: str
    parse: Callable[[str], T]
    unset: T

    def get(self, env: Optional[Mapping[str, str]] = None) -> T:
        """The value in ``env`` (this process's environment when None); :attr:`unset` when the variable is
        unset or blank. A bad value raises :class:`~micros_rt.exceptions.SettingError`."""
        raw = self.text(env)
        if not raw:
            return self.unset
        try:
            return self.parse(raw)
        except ValueError as exc:
            raise SettingError(f"{self.name}={raw!r} {exc}; expected {self.takes} (unset: {self.default})") from None

    def text(self, env: Optional[Mapping[str, str]] = None) -> str:
        """The variable's text as given, stripped ("" when unset)."""
        return (os.environ if env is None else env).get(self.name, "").strip()


def _switch(raw: str) -> bool:
    word = raw.lower()
    if word in _ON:
        return True
    if word in _OFF:
        return False
    raise ValueError("is not on or off")


def _mode(raw: str) -> str:
    word = raw.lower()
    if word == "auto":
        return "auto"
    try:
        return "on" if _switch(word) else "off"
    except ValueError:
        raise ValueError("is not on, off or auto") from None


def _path(raw: str) -> str:
    return raw


def _cache(raw: str) -> Union[bool, Path]:
    try:
        return _switch(raw)
    except ValueError:
        return Path(raw).expanduser()


def _seconds(raw: str) -> float:
    try:
        value = float(raw)
    except ValueError:
        raise ValueError("is not a number of seconds") from None
    if not 0.5 <= value <= 3600.0:
        raise ValueError("is out of range")
    return value


#: The smallest UDP send buffer micros_rt accepts (bytes; the kernel doubles what is asked, see socket(7)).
MIN_SEND_BUFFER = 4096


def _bytes(raw: str) -> int:
    match = re.match(r"^([0-9]+)\s*(k|kb|kib|m|mb|mib)?$", raw, re.IGNORECASE)
    if not match:
        raise ValueError("is not a size in bytes")
    unit = (match.group(2) or "").lower()[:1]
    size = int(match.group(1)) * {"": 1, "k": 1024, "m": 1024 * 1024}[unit]
    if size < MIN_SEND_BUFFER:
        raise ValueError("is too small")
    return size


def _count(raw: str) -> int:
    try:
        value = int(raw)
    except ValueError:
        raise ValueError("is not a whole number") from None
    if value < 0:
        raise ValueError("is negative")
    return value


_SWITCH = "on or off (1/0, true/false, yes/no)"

QOS_PROFILE: Setting[Optional[str]] = Setting(
    "MICROS_RT_QOS_PROFILE", "a path to a YAML QoS profile", "no profile",
    "the QoS profile of every node started without one in code (`init_node(qos_profile=...)`, "
    "`micros-rt run --profile`)", _path, None)
DISABLE_DDS: Setting[bool] = Setting(
    "MICROS_RT_DISABLE_DDS", _SWITCH, "off",
    "on: no DDS in this process; every topic uses TCPROS or shared memory", _switch, False)
DISABLE_SHM: Setting[bool] = Setting(
    "MICROS_RT_DISABLE_SHM", _SWITCH, "off",
    "on: no shared memory (iceoryx2); nodes of one host use DDS or TCPROS", _switch, False)
ROS2: Setting[Optional[str]] = Setting(
    "MICROS_RT_ROS2", "on, off or auto", "the profile's `ros2:`, else auto",
    "whether topics are ROS 2 topics too: on (a DDS writer and reader with every topic), off (DDS only where "
    "a peer needs it), auto (as off; while a ROS 2 node is on the domain the host's watcher announces the nodes to "
    "ROS 2, and a node whose topic a ROS 2 node uses becomes as on)", _mode, None)
DISABLE_ROS2_SERVICES: Setting[bool] = Setting(
    "MICROS_RT_DISABLE_ROS2_SERVICES", _SWITCH, "off",
    "on: services and actions stay ROS 1 only (no rclpy helper process)", _switch, False)
ROS2_PYTHON: Setting[Optional[str]] = Setting(
    "MICROS_RT_ROS2_PYTHON", "a path to a Python with rclpy", "a `.venv-ros2` beside the source or in the "
    "working directory", "the interpreter of the helper process that serves services and actions toward ROS 2",
    _path, None)
LEASE_DURATION: Setting[Optional[float]] = Setting(
    "MICROS_RT_LEASE_DURATION", "seconds, 0.5 to 3600",
    "15 s on a network interface; on loopback 5 s, or 1.5 s with MICROS_RT_DISABLE_SHM",
    "the DDS participant lease: how long a DDS peer that stopped answering counts as alive", _seconds, None)
SEND_BUFFER: Setting[Optional[int]] = Setting(
    "MICROS_RT_SEND_BUFFER", f"bytes, at least {MIN_SEND_BUFFER} (16384, 16kB, 1MB)", "Cyclone's own",
    "the UDP send buffer of this process's DDS sockets: small keeps little queued in a slow link (never for a "
    "process with HIGH topics)", _bytes, None)
TYPE_CACHE: Setting[Union[bool, Path]] = Setting(
    "MICROS_RT_TYPE_CACHE", "on, off, or a directory", "on, in ~/.cache/micros_rt/xtypes ($XDG_CACHE_HOME)",
    "where DDS type data is cached between starts of a node (25-60 ms per message type saved)", _cache, True)
RECEIVE_PRIORITY: Setting[bool] = Setting(
    "MICROS_RT_RECEIVE_PRIORITY", _SWITCH, "on",
    "off: delivery threads keep the process's nice value and switch interval (a node that sets its own)",
    _switch, True)
MALLOC_ARENA_MAX: Setting[int] = Setting(
    "MICROS_RT_MALLOC_ARENA_MAX", "a whole number, 0 or more", "2",
    "glibc malloc arenas of a node (0: glibc's own); caps the memory rospy's XML-RPC threads keep", _count, 2)
MALLOC_KEEP_LARGE: Setting[bool] = Setting(
    "MICROS_RT_MALLOC_KEEP_LARGE", _SWITCH, "on",
    "on: large blocks stay in the heap (glibc's mmap and trim thresholds raised), so big messages reuse memory",
    _switch, True)

#: Every setting, in the order docs/troubleshooting.md#settings lists them.
SETTINGS: Tuple[Setting[Any], ...] = (QOS_PROFILE, DISABLE_DDS, DISABLE_SHM, ROS2, DISABLE_ROS2_SERVICES, ROS2_PYTHON,
                                      LEASE_DURATION, SEND_BUFFER, TYPE_CACHE, RECEIVE_PRIORITY, MALLOC_ARENA_MAX,
                                      MALLOC_KEEP_LARGE)


def check(env: Optional[Mapping[str, str]] = None) -> None:
    """Raise one :class:`~micros_rt.exceptions.SettingError` naming every setting in ``env`` (this process's
    environment when None) with a bad value."""
    env = os.environ if env is None else env
    problems: List[str] = []
    for setting in SETTINGS:
        try:
            setting.get(env)
        except SettingError as exc:
            problems.append(str(exc))
    if problems:
        raise SettingError("; ".join(problems))


def unknown(env: Optional[Mapping[str, str]] = None) -> List[str]:
    """``MICROS_RT_*`` variables in ``env`` that are no setting of micros_rt (a typo, or a tool's own)."""
    env = os.environ if env is None else env
    known = {s.name for s in SETTINGS}
    return sorted(name for name in env if name.startswith("MICROS_RT_") and name not in known)
