"""Test harness: real rosmaster, real peer processes, loopback-only DDS.

Everything here starts real things (the team's rule: real peers, not mocks):

* ``RosMaster``  - Debian's ``rosmaster --core`` on a free 127.0.0.1 port, private ROS_HOME/ROS_LOG_DIR.
* ``Peer``       - a subprocess printing one JSON object per stdout line (tests/peers/*.py).
* helpers        - ``wait_until``, ``rostopic``, ``rosnode``, ``master_call``, ``node_call``, ``eth0_tx_packets``.

The pytest fixtures that wrap these live in tests/conftest.py.
No micros_rt import here: the harness must work even when the library is broken.
"""

from __future__ import annotations

import collections
import json
import os
import signal
import socket
import subprocess
import tempfile
import threading
import time
import xmlrpc.client
from pathlib import Path
from typing import Any, Callable, Deque, Dict, Iterator, List, Mapping, Optional, Sequence, Union

REPO_ROOT = Path(__file__).resolve().parent.parent
TESTS_DIR = REPO_ROOT / "tests"
PEERS_DIR = TESTS_DIR / "peers"

MICROS_RT_PYTHON = str(REPO_ROOT / ".venv" / "bin" / "python")
STOCK_PYTHON = "/usr/bin/python3"
ROS2_PYTHON = str(REPO_ROOT / ".venv-ros2" / "bin" / "python")

ROSMASTER = "/usr/bin/rosmaster"
ROSTOPIC = "/usr/bin/rostopic"
ROSNODE = "/usr/bin/rosnode"

STOCK_TALKER = PEERS_DIR / "stock_talker.py"
STOCK_LISTENER = PEERS_DIR / "stock_listener.py"
ROS2_PEER = PEERS_DIR / "ros2_peer.py"

CYCLONEDDS_CONFIG = TESTS_DIR / "cyclonedds_loopback.xml"
FASTDDS_PROFILE = PEERS_DIR / "fastdds_loopback.xml"

ETH0_TX_PACKETS = Path("/sys/class/net/eth0/statistics/tx_packets")

# Variables that would leak the caller's ROS / Python setup into children.
_SCRUB_ENV = (
    "ROS_HOSTNAME", "ROS_NAMESPACE", "PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV",
    "FASTDDS_DEFAULT_PROFILES_FILE", "RMW_IMPLEMENTATION", "ROS_LOCALHOST_ONLY",
    "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER", "AMENT_PREFIX_PATH",
)


# --------------------------------------------------------------------------- generic helpers

def wait_still(value: Callable[[], Any], still_for: float, timeout: float, interval: float = 0.05) -> Any:
    """Poll ``value()`` until it has not changed for ``still_for`` seconds (or ``timeout`` passed); return it.

    For "nothing more is coming": the last messages a loaded machine reads late are counted before a snapshot.
    """
    last, since = value(), time.monotonic()
    bound = since + timeout
    while time.monotonic() - since < still_for and time.monotonic() < bound:
        time.sleep(interval)
        now = value()
        if now != last:
            last, since = now, time.monotonic()
    return last


def wait_until(cond: Callable[[], Any], timeout: float, interval: float = 0.02, message: str = "") -> Any:
    """Poll ``cond()`` until it returns something truthy; return that value.

    Raises AssertionError(message) after ``timeout`` seconds. Exceptions from ``cond`` propagate.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = cond()
        if value:
            return value
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out after {timeout:.1f}s waiting for {message or cond!r}")
        time.sleep(interval)


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def eth0_tx_packets() -> Optional[int]:
    """Packets sent on eth0 so far (None when there is no eth0)."""
    try:
        return int(ETH0_TX_PACKETS.read_text().strip())
    except OSError:
        return None


def dds_domain_id_for_pid(pid: Optional[int] = None) -> int:
    """A per-test-run DDS domain id in 1..200 (never 0, the default everyone else uses)."""
    return 1 + (os.getpid() if pid is None else pid) % 200


def dds_env(domain_id: int) -> Dict[str, str]:
    """Environment for loopback-only DDS on ``domain_id`` (Cyclone and Fast DDS/rclpy), and no MICROS_RT_* setting:
    the suite runs what users get (a module that tests another mode declares it, see :data:`DDS_BETWEEN_NODES`)."""
    return {
        "ROS_DOMAIN_ID": str(domain_id),
        # what users get otherwise: shared memory between nodes of one host, ROS 2 visibility auto. A module that
        # tests another mode says so with ``pytest.mark.env(...)`` and why (tests/conftest.py applies it)
        "CYCLONEDDS_URI": CYCLONEDDS_CONFIG.as_uri(),
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }


#: The mode of a module that tests the DDS plane between micros_rt nodes (QoS on the wire, lossless DDS, discovery,
#: robustness): shared memory off, so two nodes of this host talk DDS as two hosts do, and every topic on DDS from
#: its start (visibility on), as between hosts, where a subscriber's DDS reader must exist before data flows.
DDS_BETWEEN_NODES = {"MICROS_RT_DISABLE_SHM": "1", "MICROS_RT_ROS2": "on",
                     "why": "the DDS plane between hosts, with two nodes of this host standing in for two hosts "
                            "(shared memory off; DDS readers and writers from each topic's start)"}


def delete_netns(names: Sequence[str]) -> None:
    """Delete network namespaces, and the files micros_rt nodes in them left in /dev/shm (the host ROS 2 watcher's
    lock and marker, one per user, namespace and domain: a real host keeps one, a test run would pile them up)."""
    for ns in names:
        try:
            inode = os.stat(f"/run/netns/{ns}").st_ino
        except OSError:
            inode = None
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=20)
        if inode is not None:
            for path in Path("/dev/shm").glob(f"micros_rt_ros2_u*_n{inode}_d*"):
                path.unlink(missing_ok=True)


def child_env(extra: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
    """os.environ without the caller's ROS/Python leftovers, plus ``extra`` and unbuffered output."""
    env = {k: v for k, v in os.environ.items() if k not in _SCRUB_ENV}
    env["PYTHONUNBUFFERED"] = "1"
    if extra:
        env.update(extra)
    return env


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float) -> None:
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host: Any) -> Any:
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def xmlrpc_proxy(uri: str, timeout: float = 5.0) -> xmlrpc.client.ServerProxy:
    return xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout), allow_none=True)


class RosApiError(AssertionError):
    """A ROS master/slave API call answered with code != 1."""

    def __init__(self, method: str, code: int, status: str, value: Any) -> None:
        super().__init__(f"{method}: code {code}: {status}")
        self.method, self.code, self.status, self.value = method, code, status, value


def _ros_api_call(uri: str, method: str, args: Sequence[Any], caller_id: str, timeout: float,
                  raw: bool) -> Any:
    result = getattr(xmlrpc_proxy(uri, timeout), method)(caller_id, *args)
    if raw:
        return result
    code, status, value = result
    if code != 1:
        raise RosApiError(method, code, status, value)
    return value


# --------------------------------------------------------------------------- rosmaster

class RosMaster:
    """A real ``rosmaster --core`` on 127.0.0.1, run by /usr/bin/python3.

    ``env`` is the full environment to give child processes (ROS_MASTER_URI, ROS_IP, ROS_HOME,
    ROS_LOG_DIR, plus the loopback DDS variables and ROS_DOMAIN_ID when ``domain_id`` is given).
    """

    def __init__(self, port: Optional[int] = None, workdir: Optional[Path] = None,
                 domain_id: Optional[int] = None, startup_timeout: float = 20.0) -> None:
        self.port = port if port is not None else free_tcp_port()
        self._own_workdir = workdir is None
        self.workdir = Path(tempfile.mkdtemp(prefix="micros_rt_master_")) if workdir is None else workdir
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.domain_id = domain_id
        self.startup_timeout = startup_timeout
        self.proc: Optional[subprocess.Popen[bytes]] = None
        self.starts = 0
        self.startup_seconds: Optional[float] = None
        extra = {
            "ROS_MASTER_URI": self.uri,
            "ROS_IP": "127.0.0.1",
            "ROS_HOME": str(self.workdir / "ros_home"),
            "ROS_LOG_DIR": str(self.workdir / "log"),
        }
        if domain_id is not None:
            extra.update(dds_env(domain_id))
        self.env: Dict[str, str] = child_env(extra)

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def pid(self) -> Optional[int]:
        return self.proc.pid if self.proc is not None else None

    @property
    def log_path(self) -> Path:
        return self.workdir / f"rosmaster.{self.starts}.log"

    def proxy(self, timeout: float = 5.0) -> xmlrpc.client.ServerProxy:
        return xmlrpc_proxy(self.uri, timeout)

    def is_up(self) -> bool:
        try:
            answer: Any = self.proxy(timeout=1.0).getPid("/micros_rt_test")
            code, _, _ = answer
            return bool(code == 1)
        except (OSError, xmlrpc.client.Error):
            return False

    def start(self) -> "RosMaster":
        if self.proc is not None and self.proc.poll() is None:
            raise RuntimeError("rosmaster already running")
        self.starts += 1
        t0 = time.monotonic()
        log = open(self.log_path, "wb")
        try:
            self.proc = subprocess.Popen(
                [STOCK_PYTHON, ROSMASTER, "--core", "-p", str(self.port)],
                env=self.env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                cwd=str(self.workdir), start_new_session=True)
        finally:
            log.close()
        proc = self.proc

        def up() -> bool:
            if proc.poll() is not None:
                raise AssertionError(f"rosmaster exited with {proc.returncode} on port {self.port}:\n"
                                     + self.log_tail())
            return self.is_up()

        try:
            wait_until(up, self.startup_timeout, interval=0.05,
                       message=f"rosmaster on port {self.port} to answer getPid")
        except BaseException:
            self.stop()
            raise
        self.startup_seconds = time.monotonic() - t0
        return self

    def log_tail(self, n: int = 30) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no log)"

    def stop(self, timeout: float = 5.0) -> None:
        proc, self.proc = self.proc, None
        if proc is None:
            return
        _stop_process(proc, timeout, first_signal=signal.SIGTERM)

    def restart(self) -> "RosMaster":
        """Stop and start again on the same port (a fresh, empty graph)."""
        self.stop()
        return self.start()

    def cleanup(self) -> None:
        self.stop()
        if self._own_workdir:
            import shutil
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> "RosMaster":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.cleanup()

    def __repr__(self) -> str:
        return f"RosMaster(uri={self.uri!r}, pid={self.pid})"


def _stop_process(proc: "subprocess.Popen[Any]", timeout: float, first_signal: int = signal.SIGINT) -> Optional[int]:
    """first_signal, then SIGTERM, then SIGKILL; each step waits at most ``timeout`` seconds."""
    for sig in (first_signal, signal.SIGTERM, signal.SIGKILL):
        if proc.poll() is not None:
            break
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=timeout if sig != signal.SIGKILL else 10.0)
            break
        except subprocess.TimeoutExpired:
            continue
    return proc.poll()


MasterLike = Union[RosMaster, str]


def _master_uri(master: MasterLike) -> str:
    return master.uri if isinstance(master, RosMaster) else master


def master_call(master: MasterLike, method: str, *args: Any, caller_id: str = "/micros_rt_test",
                timeout: float = 5.0) -> Any:
    """Call the ROS master API; return the value of ``[code, status, value]``.

    Raises RosApiError (an AssertionError) when code != 1, e.g. lookupNode of an unknown node.
    """
    return _ros_api_call(_master_uri(master), method, args, caller_id, timeout, raw=False)


def master_call_raw(master: MasterLike, method: str, *args: Any, caller_id: str = "/micros_rt_test",
                    timeout: float = 5.0) -> Any:
    """Like master_call but returns the whole ``[code, status, value]``."""
    return _ros_api_call(_master_uri(master), method, args, caller_id, timeout, raw=True)


def node_call(uri: str, method: str, *args: Any, caller_id: str = "/micros_rt_test",
              timeout: float = 5.0) -> Any:
    """Call a node's slave API (getBusInfo, getPublications, requestTopic, ...); value of the triple."""
    return _ros_api_call(uri, method, args, caller_id, timeout, raw=False)


def node_call_raw(uri: str, method: str, *args: Any, caller_id: str = "/micros_rt_test",
                  timeout: float = 5.0) -> Any:
    return _ros_api_call(uri, method, args, caller_id, timeout, raw=True)


def lookup_node(master: MasterLike, name: str) -> str:
    """XML-RPC URI of node ``name`` (raises RosApiError when unknown)."""
    return str(master_call(master, "lookupNode", name))


def system_state(master: MasterLike) -> Dict[str, Dict[str, List[str]]]:
    """getSystemState as {"publishers": {topic: [nodes]}, "subscribers": {...}, "services": {...}}."""
    pubs, subs, srvs = master_call(master, "getSystemState")
    return {
        "publishers": {t: list(n) for t, n in pubs},
        "subscribers": {t: list(n) for t, n in subs},
        "services": {t: list(n) for t, n in srvs},
    }


def _run_tool(tool: str, master: RosMaster, args: Sequence[str], timeout: float, check: bool,
              env: Optional[Mapping[str, str]]) -> "subprocess.CompletedProcess[str]":
    full_env = dict(master.env)
    if env:
        full_env.update(env)
    try:
        cp = subprocess.run([STOCK_PYTHON, tool, *args], env=full_env, stdin=subprocess.DEVNULL,
                            capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"{Path(tool).name} {' '.join(args)} timed out after {timeout}s\n"
                             f"stdout: {e.stdout!r}\nstderr: {e.stderr!r}") from None
    if check and cp.returncode != 0:
        raise AssertionError(f"{Path(tool).name} {' '.join(args)} exited {cp.returncode}\n"
                             f"stdout:\n{cp.stdout}\nstderr:\n{cp.stderr}")
    return cp


def rostopic(master: RosMaster, *args: str, timeout: float = 15.0, check: bool = True,
             env: Optional[Mapping[str, str]] = None) -> "subprocess.CompletedProcess[str]":
    """Run stock ``rostopic ARGS`` against ``master``; raises AssertionError on timeout or (check) failure."""
    return _run_tool(ROSTOPIC, master, args, timeout, check, env)


def rosnode(master: RosMaster, *args: str, timeout: float = 15.0, check: bool = True,
            env: Optional[Mapping[str, str]] = None) -> "subprocess.CompletedProcess[str]":
    """Run stock ``rosnode ARGS`` against ``master``."""
    return _run_tool(ROSNODE, master, args, timeout, check, env)


# --------------------------------------------------------------------------- peers

Event = Dict[str, Any]
Predicate = Union[str, Callable[[Event], bool]]


def _as_predicate(pred: Predicate) -> Callable[[Event], bool]:
    if isinstance(pred, str):
        kind = pred
        return lambda e: e.get("event") == kind
    return pred


_DECODER = json.JSONDecoder()


def split_events(line: str) -> List[Event]:
    """The events in one stdout line: JSON objects, and ``_raw`` for any other text.

    A peer's JSON object and a log line written by another thread of the same process can share
    a line (``print`` writes the text and its newline separately); both are kept.
    """
    events: List[Event] = []
    rest = line
    while rest.startswith("{"):
        try:
            ev, end = _DECODER.raw_decode(rest)
        except ValueError:
            break
        if not isinstance(ev, dict):
            break
        events.append(ev)
        rest = rest[end:]
    if rest.strip():
        events.append({"event": "_raw", "line": rest})
    return events


class Peer:
    """A subprocess that prints one JSON object per stdout line.

    Non-JSON stdout lines are recorded as ``{"event": "_raw", "line": ...}``. Every event gets
    ``"_rx"`` (time.time() when the harness read it). stderr is kept (last 200 lines).
    """

    def __init__(self, argv: Sequence[str], env: Optional[Mapping[str, str]] = None, *,
                 name: Optional[str] = None, cwd: Optional[Union[str, Path]] = None) -> None:
        self.argv = [str(a) for a in argv]
        self.name = name or Path(self.argv[1] if len(self.argv) > 1 else self.argv[0]).name
        self._events: List[Event] = []
        self._stderr: Deque[str] = collections.deque(maxlen=200)
        self._cond = threading.Condition()
        self._stdout_done = False
        self.proc: subprocess.Popen[str] = subprocess.Popen(
            self.argv, env=dict(env) if env is not None else child_env(), cwd=str(cwd or REPO_ROOT),
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, bufsize=1, start_new_session=True)
        self._threads = [
            threading.Thread(target=self._read_stdout, name=f"{self.name}-stdout", daemon=True),
            threading.Thread(target=self._read_stderr, name=f"{self.name}-stderr", daemon=True),
        ]
        for t in self._threads:
            t.start()

    # -- readers
    def _read_stdout(self) -> None:
        assert self.proc.stdout is not None
        try:
            for line in self.proc.stdout:
                line = line.rstrip("\n")
                if not line:
                    continue
                rx = time.time()
                with self._cond:
                    for ev in split_events(line):
                        ev["_rx"] = rx
                        self._events.append(ev)
                    self._cond.notify_all()
        finally:
            with self._cond:
                self._stdout_done = True
                self._cond.notify_all()

    def _read_stderr(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self._stderr.append(line.rstrip("\n"))

    # -- queries
    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def returncode(self) -> Optional[int]:
        return self.proc.poll()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def events(self, kind: Optional[str] = None) -> List[Event]:
        """A snapshot of the events so far (only those with ``"event" == kind`` when given)."""
        with self._cond:
            return [e for e in self._events if kind is None or e.get("event") == kind]

    def count(self, kind: str) -> int:
        return len(self.events(kind))

    def stderr_tail(self, n: int = 40) -> str:
        return "\n".join(list(self._stderr)[-n:])

    def _failure(self, what: str, timeout: float) -> AssertionError:
        evs = self.events()
        return AssertionError(
            f"peer {self.name} (pid {self.pid}, returncode {self.returncode}): {what} "
            f"within {timeout:.1f}s\nargv: {' '.join(self.argv)}\n"
            f"last events ({len(evs)} total): {evs[-5:]}\nstderr tail:\n{self.stderr_tail()}")

    def wait_for(self, predicate: Predicate, timeout: float = 10.0, *, start: int = 0) -> Event:
        """The first event (index >= start) matching ``predicate`` (an event kind or a callable).

        Fails fast (AssertionError with the stderr tail) when the peer's stdout closes first.
        """
        pred = _as_predicate(predicate)
        deadline = time.monotonic() + timeout
        i = start
        with self._cond:
            while True:
                while i < len(self._events):
                    if pred(self._events[i]):
                        return self._events[i]
                    i += 1
                if self._stdout_done:
                    raise self._failure(f"exited without the awaited event ({predicate!r})", timeout)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise self._failure(f"no event matching {predicate!r}", timeout)
                self._cond.wait(left)

    def wait_for_count(self, kind: str, n: int, timeout: float = 10.0) -> List[Event]:
        """Wait until at least ``n`` events of ``kind``; return them."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                got = [e for e in self._events if e.get("event") == kind]
                if len(got) >= n:
                    return got
                if self._stdout_done:
                    raise self._failure(f"exited with {len(got)}/{n} {kind!r} events", timeout)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise self._failure(f"only {len(got)}/{n} {kind!r} events", timeout)
                self._cond.wait(left)

    def wait(self, timeout: float = 30.0) -> int:
        """Wait for the peer to exit by itself; return its exit code (AssertionError on timeout)."""
        try:
            rc = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise self._failure("did not exit", timeout) from None
        self._join_readers()
        return rc

    def _join_readers(self) -> None:
        for t in self._threads:
            t.join(timeout=2.0)

    def stop(self, timeout: float = 5.0) -> Optional[int]:
        """SIGINT, then SIGTERM, then SIGKILL (each bounded by ``timeout``); return the exit code."""
        rc = _stop_process(self.proc, timeout, first_signal=signal.SIGINT)
        self._join_readers()
        return rc

    def __enter__(self) -> "Peer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"Peer({self.name!r}, pid={self.pid}, rc={self.returncode})"


def stock_talker_argv(*args: str) -> List[str]:
    return [STOCK_PYTHON, str(STOCK_TALKER), *args]


def stock_listener_argv(*args: str) -> List[str]:
    return [STOCK_PYTHON, str(STOCK_LISTENER), *args]


def ros2_peer_argv(*args: str) -> List[str]:
    return [ROS2_PYTHON, str(ROS2_PEER), *args]


class Spawner:
    """Creates peers and stops all of them at ``close()`` (the ``spawn`` fixture)."""

    def __init__(self, default_env: Optional[Mapping[str, str]] = None) -> None:
        self.default_env = dict(default_env) if default_env is not None else None
        self.peers: List[Peer] = []

    def __call__(self, argv: Sequence[str], env: Optional[Mapping[str, str]] = None, *,
                 name: Optional[str] = None, cwd: Optional[Union[str, Path]] = None) -> Peer:
        use_env = env if env is not None else self.default_env
        peer = Peer(argv, use_env, name=name, cwd=cwd)
        self.peers.append(peer)
        return peer

    def __iter__(self) -> Iterator[Peer]:
        return iter(self.peers)

    def close(self) -> None:
        # SIGINT everyone first so they shut down in parallel, then stop each (bounded).
        for p in self.peers:
            if p.alive():
                try:
                    p.proc.send_signal(signal.SIGINT)
                except ProcessLookupError:
                    pass
        for p in self.peers:
            p.stop()
