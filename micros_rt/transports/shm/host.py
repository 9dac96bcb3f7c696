"""Whether two processes can share memory, and this process's iceoryx2 node.

Two micros_rt processes use shared memory when they run on the same machine (boot id), in the same network
and mount namespaces (the test suite's and cross-host benchmark's "hosts" are network namespaces of one
machine: they must use the network) and as the same Unix user (iceoryx2's files in ``/dev/shm`` are the
creator's). Everything else, and a machine without the ``iceoryx2`` wheel (x86_64 Linux with glibc >= 2.34
only: an aarch64 robot has none), uses DDS or TCPROS, and ``unavailable_reason()`` says why in words.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Mapping, Optional

__all__ = ["MIN_FREE_BYTES", "cleanup_dead_nodes", "host_identity", "iceoryx2", "shm_node", "unavailable_reason"]

#: ``/dev/shm`` with less room than this is not used (a full tmpfs makes iceoryx2 fail mid-stream).
MIN_FREE_BYTES = 64 << 20

_lock = threading.Lock()
_identity: Optional[str] = None
_reason: Optional[str] = ""     # "" until checked
_module: Any = None
_node: Any = None


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError:
        return "?"


def _ns(kind: str) -> str:
    try:
        return str(os.stat(f"/proc/self/ns/{kind}").st_ino)
    except OSError:
        return "?"


def host_identity() -> str:
    """``<boot id>/<network namespace>/<mount namespace>/<uid>``: equal for two processes that can share
    iceoryx2 memory."""
    global _identity
    if _identity is None:
        _identity = f"{_read('/proc/sys/kernel/random/boot_id')}/{_ns('net')}/{_ns('mnt')}/{os.getuid()}"
    return _identity


def iceoryx2() -> Any:
    """The iceoryx2 module (raises RuntimeError, in words, where it cannot be used)."""
    global _reason
    if _module is None:
        with _lock:
            if _reason == "":
                _reason = _check()
        if _module is None:
            raise RuntimeError(_reason or "iceoryx2 is not loaded")
    return _module


def unavailable_reason(env: Mapping[str, str] = os.environ) -> Optional[str]:
    """None when this process can use shared memory, else why not, in words (checked once; ``env``'s
    MICROS_RT_DISABLE_SHM each time)."""
    global _reason
    if env.get("MICROS_RT_DISABLE_SHM", "") not in ("", "0"):
        return "turned off by MICROS_RT_DISABLE_SHM"
    with _lock:
        if _reason == "":
            _reason = _check()
        return _reason


def _check() -> Optional[str]:
    global _module
    try:
        st = os.statvfs("/dev/shm")
    except OSError as exc:
        return f"/dev/shm is not there ({exc})"
    if not os.access("/dev/shm", os.W_OK):
        return "/dev/shm is not writable by this user"
    free = st.f_bavail * st.f_frsize
    if free < MIN_FREE_BYTES:
        return (f"/dev/shm has {free >> 20} MiB free, less than the {MIN_FREE_BYTES >> 20} MiB micros_rt needs "
                f"(enlarge it: mount -o remount,size=1G /dev/shm)")
    try:
        import iceoryx2 as iox2
    except ImportError as exc:
        return (f"the iceoryx2 package is not installed ({exc}; pip install iceoryx2: wheels exist for x86_64 "
                f"Linux with glibc 2.34 or newer)")
    except Exception as exc:  # a wheel for another platform, a broken install
        return f"the iceoryx2 package does not load: {exc}"
    iox2.set_log_level(iox2.LogLevel.Error)
    _module = iox2
    return None


def shm_node() -> Any:
    """This process's iceoryx2 node (created on first use; one per process). Raises ``RuntimeError`` when
    shared memory is unavailable."""
    global _node
    if _node is not None:
        return _node
    reason = unavailable_reason()
    if reason is not None:
        raise RuntimeError(reason)
    with _lock:
        if _node is None:
            iox2 = _module
            builder = iox2.NodeBuilder.new()
            mode = getattr(iox2.SignalHandlingMode, "Disabled", None)
            if mode is not None:
                builder = builder.signal_handling_mode(mode)  # SIGINT/SIGTERM stay rospy's
            _node = builder.create(iox2.ServiceType.Ipc)
        return _node


_last_cleanup = 0.0
#: At most one clean-up per this many seconds per process (every link and channel asks every 0.5 s).
CLEANUP_INTERVAL = 0.5


def cleanup_dead_nodes() -> None:
    """Reclaim what SIGKILLed iceoryx2 processes left (their shared memory and their ports in our services),
    so a dead peer's channel reads as unconnected."""
    global _last_cleanup
    node = _node
    if node is None:
        return
    now = time.monotonic()
    if now - _last_cleanup < CLEANUP_INTERVAL:
        return
    _last_cleanup = now
    try:
        node.try_cleanup_dead_nodes()
    except Exception:  # another process cleaning at the same moment; the next round will
        pass
