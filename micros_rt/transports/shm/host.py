"""Whether two processes can share memory, and this process's iceoryx2 node.

Two micros_rt processes use shared memory when they run on the same machine (boot id), in the same network
and mount namespaces (the test suite's and cross-host benchmark's "hosts" are network namespaces of one
machine: they must use the network) and as the same Unix user (iceoryx2's files in ``/dev/shm`` are the
creator's). Everything else, and a machine without the ``iceoryx2`` wheel (x86_64 Linux with glibc >= 2.34
only: an aarch64 robot has none), uses DDS or TCPROS, and ``unavailable_reason()`` says why in words.
"""

from __future__ import annotations

import os
import select
import stat
import threading
from typing import Any, Mapping, Optional, Set

from ... import settings

__all__ = ["ATTACH_TIMEOUT", "MIN_FREE_BYTES", "cleanup_dead_nodes", "close_node", "commit_segments", "host_identity",
           "iceoryx2", "iceoryx2_root", "permission_problem", "PeerProcess", "process_alive", "shm_free_bytes", "shm_node",
           "unavailable_reason", "wait_set", "warn_if_full", "why_failed"]

#: How long a channel waits for its subscriber's port (a 60-node graph starting on 2 cores took more than 10 s).
ATTACH_TIMEOUT = 60.0
#: ``/dev/shm`` with less room than this is not used (a full tmpfs makes iceoryx2 fail mid-stream).
MIN_FREE_BYTES = 64 << 20

_lock = threading.Lock()
_identity: Optional[str] = None
_reason: Optional[str] = ""     # "" until checked
_module: Any = None
_node: Any = None
#: iceoryx2 data segments of this process already committed (their paths in /dev/shm)
_committed: Set[str] = set()
_commit_lock = threading.Lock()


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
    """``<boot id>/<network namespace>/<mount namespace>/<uid>/<iceoryx2 directory scheme>``: equal for two
    processes that can share iceoryx2 memory (micros_rt before issue 46 kept it in /tmp/iceoryx2 and sent four
    parts: a node of that version is told apart, not given a channel it cannot open)."""
    global _identity
    if _identity is None:
        _identity = (f"{_read('/proc/sys/kernel/random/boot_id')}/{_ns('net')}/{_ns('mnt')}/{os.getuid()}/"
                     f"{_ROOT_SCHEME}")
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
    if settings.DISABLE_SHM.get(env):
        return "turned off by MICROS_RT_DISABLE_SHM"
    with _lock:
        if _reason == "":
            _reason = _check()
        return _reason


#: the iceoryx2 directory scheme, part of the host identity: "u" one directory per Unix user (iceoryx2_root)
_ROOT_SCHEME = "u"


def iceoryx2_root(uid: Optional[int] = None) -> str:
    """iceoryx2's directory of micros_rt for Unix user ``uid`` (this process's): one per user. iceoryx2's default,
    /tmp/iceoryx2, is made by its first user with mode 0750, and every other user then failed (issue 46: after a
    root node ran, two nodes of another user fell back to DDS, told that /dev/shm might be full). Processes of two
    users never share iceoryx2 memory anyway."""
    return f"/tmp/micros_rt-iceoryx2-{os.getuid() if uid is None else uid}/"


def permission_problem(root: Optional[str] = None) -> Optional[str]:
    """Why this user cannot use its iceoryx2 directory (``root``: :func:`iceoryx2_root`), in words, or None."""
    root = root or iceoryx2_root()
    uid = os.getuid()
    for path in (root, root + "nodes", root + "services"):
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            continue  # iceoryx2 makes it
        except OSError as exc:
            return f"iceoryx2's directory {path} cannot be read ({exc.strerror})"
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or not os.access(path, os.W_OK | os.X_OK):
            return (f"iceoryx2's directory {path} belongs to uid {st.st_uid} with mode {stat.S_IMODE(st.st_mode):04o}"
                    f"{'' if stat.S_ISDIR(st.st_mode) else ' and is no directory'}: this user (uid {uid}) cannot "
                    f"use it, a permission problem, not a full /dev/shm (remove {root}: micros_rt makes one per "
                    f"user)")
    return None


def why_failed(exc: BaseException) -> str:
    """The cause of an iceoryx2 failure in words: permissions, a full /dev/shm, or iceoryx2's own words."""
    problem = permission_problem()
    if problem is not None:
        return problem
    free = shm_free_bytes()
    if free < MIN_FREE_BYTES:
        return f"/dev/shm is full ({free >> 20} MiB free: df -h /dev/shm) ({type(exc).__name__}: {exc})"
    return (f"iceoryx2 refused ({type(exc).__name__}: {exc}); /dev/shm has {free >> 20} MiB free and "
            f"{iceoryx2_root()} is this user's: iceoryx2's limits (ports, nodes) may be reached")


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
    try:
        os.mkdir(iceoryx2_root(), 0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        return f"cannot make iceoryx2's directory {iceoryx2_root()} ({exc.strerror})"
    problem = permission_problem()
    if problem is not None:
        return problem
    _module = iox2
    return None


def _config() -> Any:
    """iceoryx2's configuration with this user's directory (:func:`iceoryx2_root`)."""
    iox2 = _module
    cfg = iox2.config.default()
    cfg.global_cfg.root_path = iox2.Path.new(iceoryx2_root())
    return cfg


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
            _node = _without_signal_handling(iox2.NodeBuilder.new().config(_config())).create(iox2.ServiceType.Ipc)
        return _node


def _without_signal_handling(builder: Any) -> Any:
    """An iceoryx2 builder that leaves SIGINT/SIGTERM to rospy: by default iceoryx2's node and wait set install
    handlers of their own that take the signal (a node then kept running after Ctrl-C until SIGKILL, which left
    its shared memory behind)."""
    mode = getattr(iceoryx2().SignalHandlingMode, "Disabled", None)
    return builder.signal_handling_mode(mode) if mode is not None else builder


def wait_set() -> Any:
    """An iceoryx2 wait set (for a delivery thread) that leaves SIGINT/SIGTERM to rospy."""
    iox2 = iceoryx2()
    return _without_signal_handling(iox2.WaitSetBuilder.new()).create(iox2.ServiceType.Ipc)


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` (of this host and user) still runs; True when unknown (0)."""
    if pid <= 0:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:  # a killed process its parent has not reaped yet is a zombie: dead for us
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


class PeerProcess:
    """A peer's process, asked on every housekeeping tick whether it still runs (for each channel and link): a
    pidfd (Linux 5.3+) polled without waiting, one system call (1.3 us here, against 14.8 us for
    :func:`process_alive`: ``kill``, then ``/proc/<pid>/stat`` opened and read for a zombie). It turns readable when
    the process exits, a zombie too, and a pid reused since cannot fool it. The pidfd is opened at the first
    question (a channel that failed to build never holds one) and let go by :meth:`close` (or with the object);
    where ``pidfd_open`` is refused (an older kernel, no descriptor left), :func:`process_alive` answers.
    Thread-safe; :meth:`close` never waits (a signal handler may run it while another thread asks)."""

    __slots__ = ("pid", "_fd", "_poll", "_dead", "_opened", "_closing", "_lock", "__weakref__")

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._fd = -1
        self._poll: Any = None  # select.poll, not select.select: descriptors above 1023 too
        self._dead = False
        self._opened = False    # pidfd_open tried
        self._closing = False   # close() came while alive() held the lock: alive() lets go
        self._lock = threading.Lock()

    def alive(self) -> bool:
        """Whether the process still runs; True when unknown (pid 0)."""
        with self._lock:
            try:
                if self._dead:
                    return False
                if not self._opened and not self._closing and self.pid > 0:
                    self._open()
                if self._fd < 0:
                    return process_alive(self.pid)
                if self._poll.poll(0):
                    self._dead = True
                    self._release()
                    return False
                return True
            finally:
                if self._closing:
                    self._release()

    def _open(self) -> None:
        self._opened = True
        try:
            self._fd = os.pidfd_open(self.pid)
        except ProcessLookupError:
            self._dead = True
            return
        except (OSError, AttributeError):
            return
        self._poll = select.poll()
        self._poll.register(self._fd, select.POLLIN)

    def close(self) -> None:
        self._closing = True
        if self._lock.acquire(blocking=False):  # else alive() lets go of it on its way out
            try:
                self._release()
            finally:
                self._lock.release()

    def _release(self) -> None:
        fd, self._fd, self._poll = self._fd, -1, None
        if fd >= 0:
            os.close(fd)

    def __del__(self) -> None:
        self._release()


def cleanup_dead_nodes() -> None:
    """Reclaim what SIGKILLed iceoryx2 processes left (their shared memory and their ports in our services).
    It scans every iceoryx2 node of the machine: called when a peer's process is known dead, not per round
    (60 processes each scanning 60 nodes twice a second cost a 60-node graph most of a core)."""
    node = _node
    if node is None:
        return
    try:
        node.try_cleanup_dead_nodes()
    except Exception:  # another process cleaning at the same moment; the next round will
        pass


def close_node() -> None:
    """Let go of this process's iceoryx2 node at shutdown (after every channel and link was closed): its
    files in /dev/shm and /tmp/iceoryx2 go with it, as they would not at interpreter exit."""
    global _node
    node, _node = _node, None
    if node is not None:
        del node
        import gc

        gc.collect()  # service factories and ports still referenced by cycles hold the node


def shm_free_bytes() -> int:
    """Bytes /dev/shm can still give (0 when it cannot be read)."""
    try:
        st = os.statvfs("/dev/shm")
    except OSError:
        return 0
    return st.f_bavail * st.f_frsize


_full_warned = 0.0


def warn_if_full(now: float, log: Any) -> None:
    """Say it (at most once a minute per process) when /dev/shm has less room than a channel may need to grow:
    committed channels go on unharmed, new or growing ones fall back or go in pieces."""
    global _full_warned
    if now - _full_warned < 60.0 or _node is None:
        return
    free = shm_free_bytes()
    if free >= 16 << 20:
        return
    _full_warned = now
    log.warning("micros_rt: /dev/shm is full (%d MiB free): shared-memory channels keep the memory they committed; "
                "new subscribers get DDS or TCPROS and lossless messages larger than a channel's slot go in "
                "pieces (df -h /dev/shm; what else fills it?)", free >> 20)


def commit_segments() -> None:
    """Commit the memory of every iceoryx2 data segment this process maps and has not committed yet.

    iceoryx2 sizes a segment with ``ftruncate``: on tmpfs that is a promise, kept page by page when a page is
    first touched; when /dev/shm filled meanwhile the kernel kills the toucher with SIGBUS (issue 46: a
    publisher died with exit 135 when ``dd`` filled /dev/shm mid-stream). ``posix_fallocate`` takes every page
    now, so the kernel says no here, as ``OSError`` (ENOSPC) turned into a TransportError in words, and a
    committed segment can never SIGBUS. Called after a publisher port is made and after a sample that may
    have grown its data segment was loaned, before a byte is written. Raises TransportError."""
    from ...exceptions import TransportError

    try:
        with open("/proc/self/maps") as f:
            mapped = {line.split(None, 5)[-1].strip() for line in f if "/dev/shm/iox2_" in line}
    except OSError:
        return
    segments = {path for path in mapped if path.endswith(".data") and not path.endswith("_mgmt.data")}
    with _commit_lock:
        _committed.intersection_update(mapped)  # forget what is no longer mapped
        for path in sorted(segments - _committed):
            try:
                fd = os.open(path, os.O_RDWR)
            except OSError:
                continue  # another process's segment this process only reads (or gone meanwhile)
            try:
                size = os.fstat(fd).st_size
                os.posix_fallocate(fd, 0, size)
            except OSError as exc:
                raise TransportError(
                    f"/dev/shm has no room for a shared-memory segment of {size >> 20} MiB ({exc.strerror}; "
                    f"{shm_free_bytes() >> 20} MiB free: df -h /dev/shm)") from exc
            finally:
                os.close(fd)
            _committed.add(path)
