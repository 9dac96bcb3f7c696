"""One relay process per transport priority of the exports: each priority's DDS traffic leaves through
sockets of its own, marked with its own DSCP.

Cyclone sends all DDS data of a participant through one transmit socket. When this was written a process had one
participant, marked with the DSCP of its highest writer, so a relay exporting a HIGH control topic and a LOW
camera in one process marked the camera's packets HIGH too, and a network that honours DSCP (Wi-Fi WMM, a
DiffServ router, an ``htb`` qdisc) could not put the control topic first. A process now has a participant per
transport priority of its writers (:meth:`micros_rt.transports.dds.backend.DDSBackend.participant_for`); the
relay keeps its processes, which also keep a LOW camera's decoding and encoding off the interpreter lock of the
HIGH exports. ``micros-rt relay`` starts a child process per transport priority its exports use (``--exports-of``), each a relay
node of its own (``<name>_<priority>``, e.g. ``relay_robot_a_high``) carrying only that priority's exports; the
first process keeps the imports and services. Measured on a 40 Mbit/s link that honours DSCP (htb), 1 kHz HIGH
control beside a 30 Hz LOW 640x480 camera: control p50 0.6 ms / p99 6.0 ms with a process per priority against
40.3 / 125.7 ms in one process (stock rospy: 11.1 / 63.7 ms).

The children's standard output comes through the first process (JSON events get ``"process": <node name>``;
their counters join the first process's ``stats`` events, see :meth:`Children.merge`);
a child that exits is started again (after 1 s, doubling up to 30 s while it keeps failing); every child ends
with the first process, also when that one is killed (``PR_SET_PDEATHSIG``).
"""

from __future__ import annotations

import ctypes
import json
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, Optional

from micros_rt.log import nonblocking_logger
from micros_rt.qos import TransportPriority

from .config import RelayConfig

__all__ = ["Children", "export_priorities", "family", "process_name"]

_log = nonblocking_logger("rosout.micros_rt.relay")

RESTART_FIRST = 1.0
RESTART_MAX = 30.0
HEALTHY_AFTER = 60.0   # a child that ran this long starts again after RESTART_FIRST


def export_priorities(config: RelayConfig) -> List[TransportPriority]:
    """The transport priorities of ``config``'s export rules, highest first."""
    return sorted({TransportPriority(int(rule.options.transport_priority)) for rule in config.exports}, reverse=True)


def process_name(name: str, priority: TransportPriority) -> str:
    """The node name of the child process exporting ``priority``: ``relay_robot_a_high``."""
    return f"{name}_{priority.name.lower()}"


def family(name: str, config: RelayConfig) -> FrozenSet[str]:
    """Node names of every process of the relay named ``name`` (what one publishes, no other sends back out)."""
    return frozenset([name, *(process_name(name, p) for p in export_priorities(config))])


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the process that started it ends (Linux ``PR_SET_PDEATHSIG``)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))
    except (OSError, AttributeError):
        pass


class Children:
    """The child relay processes (see the module's text). ``argv_for(priority)`` is a child's command line;
    ``write(line)`` puts a line on the first process's standard output."""

    def __init__(self, priorities: List[TransportPriority], argv_for: Callable[[TransportPriority], List[str]],
                 names: Callable[[TransportPriority], str], write: Callable[[str], None]) -> None:
        self._argv_for = argv_for
        self._names = names
        self._write = write
        self._priorities = priorities
        self._closing = threading.Event()
        self._lock = threading.Lock()
        self._procs: Dict[TransportPriority, "subprocess.Popen[str]"] = {}
        self._threads: List[threading.Thread] = []
        self._stats: Dict[str, Dict[str, Any]] = {}   # node name -> its latest stats event
        self.restarts = 0

    def start(self) -> "Children":
        for priority in self._priorities:
            self._spawn(priority)
            thread = threading.Thread(target=self._watch, args=(priority,), daemon=True,
                                      name=f"micros_rt relay child {priority.name.lower()}")
            thread.start()
            self._threads.append(thread)
        return self

    def _spawn(self, priority: TransportPriority) -> "subprocess.Popen[str]":
        proc = subprocess.Popen(self._argv_for(priority), stdout=subprocess.PIPE, stdin=subprocess.DEVNULL,
                                text=True, preexec_fn=_die_with_parent)
        with self._lock:
            self._procs[priority] = proc
        return proc

    def _forward(self, name: str, line: str) -> None:
        try:
            event = json.loads(line)
        except ValueError:
            event = None
        if isinstance(event, dict):
            if event.get("event") == "stats":
                with self._lock:
                    self._stats[name] = event
                return
            event["process"] = name
            line = json.dumps(event, default=str)
        self._write(line)

    def merge(self, snapshot: Dict[str, Any]) -> Dict[str, Any]:
        """``snapshot`` (the first process's counters) with each child's latest: its exports (each with
        ``"process"``) and what it did not carry."""
        with self._lock:
            latest = dict(self._stats)
        merged = dict(snapshot, exports=list(snapshot.get("exports", [])),
                      not_carried=dict(snapshot.get("not_carried", {})))
        for name, event in sorted(latest.items()):
            merged["exports"] += [dict(export, process=name) for export in event.get("exports", [])]
            merged["not_carried"].update(event.get("not_carried", {}))
        return merged

    def _watch(self, priority: TransportPriority) -> None:
        name = self._names(priority)
        pause = RESTART_FIRST
        while True:
            with self._lock:
                proc = self._procs[priority]
            started = time.monotonic()
            assert proc.stdout is not None
            for line in proc.stdout:
                self._forward(name, line.rstrip("\n"))
            code = proc.wait()
            if self._closing.is_set():
                return
            pause = RESTART_FIRST if time.monotonic() - started > HEALTHY_AFTER else pause
            _log.error("micros_rt: relay process %s (the %s exports) exited with code %s; starting it again in "
                       "%.0f s", name, priority.name, code, pause)
            if self._closing.wait(pause):
                return
            pause = min(pause * 2, RESTART_MAX)
            self.restarts += 1
            self._spawn(priority)

    def pids(self) -> List[int]:
        with self._lock:
            return [proc.pid for proc in self._procs.values()]

    def close(self, timeout: float = 10.0) -> None:
        self._closing.set()
        with self._lock:
            procs: List["subprocess.Popen[str]"] = list(self._procs.values())
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)   # the relay's own Ctrl-C path: final stats, clean unregistering
        deadline = time.monotonic() + timeout
        for proc in procs:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for thread in self._threads:
            thread.join(timeout=2.0)


def child_argv(config_path: str, name: str, parent: str, priority: TransportPriority, *, poll_period: float,
               json_events: bool, stats_period: float, ros_args: List[str],
               python: Optional[str] = None) -> List[str]:
    """The command line of the child exporting ``priority``."""
    argv = [python or sys.executable, "-m", "micros_rt.bridges.relay", "--config", config_path, "--name", name,
            "--exports-of", priority.name, "--family-of", parent, "--poll-period", str(poll_period)]
    if json_events:
        argv += ["--json", "--stats-period", str(stats_period)]
    return argv + [a for a in ros_args if not a.startswith("__name:=")]
