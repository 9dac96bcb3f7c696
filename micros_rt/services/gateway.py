"""The micros_rt side of the ROS 2 service helper (:mod:`micros_rt.services.ros2_helper`).

One helper per host, user, DDS domain and ROS 2 environment (:func:`helper_address`), shared by every micros_rt
process that has services or actions toward ROS 2: the first process that needs it starts it with the Python of a
ROS 2 installation (``MICROS_RT_ROS2_PYTHON``, else ``.venv-ros2/bin/python`` beside the micros_rt source tree or in
the working directory), the others connect to it. It is a session of its own (a Ctrl-C of the process that started
it does not stop it) and exits a few seconds after the last process left. Each process has its own connection and
its own rclpy node in the helper (``ros2 node list`` shows ``<node>_services`` per process); requests and replies
cross the connection as serialized ROS 2 messages (the DDS codec of :mod:`micros_rt.transports.dds.types`).

Its DDS participant follows micros_rt's network rule (:mod:`micros_rt.transports.dds.participant`): on a loopback
node (``ROS_IP``/``ROS_HOSTNAME`` loopback) Fast DDS gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a profile
that whitelists 127.0.0.1, unless the environment already names a Fast DDS profile.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import socket
import subprocess
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from .. import settings
from ..exceptions import MicrosRtError
from ..log import nonblocking_logger
from .helper_protocol import (A_CANCEL, A_CLIENT, A_DONE, A_FEEDBACK, A_FORGET, A_READY, A_SEND, A_SERVE, A_UNSERVE,
                              A_VERDICT, ADVERTISE, CALL, CANCEL, CLIENT, ERROR, FAIL, G_ACCEPTED, G_CANCEL, G_FEEDBACK,
                              G_GOAL, G_RESULT, HELLO, LOG, READY, REQUEST, RESPONSE, RESULT, SERVICE_NAMES,
                              STATUS, UNADVERTISE, encode, read_frame)
from ..transports.dds.participant import HELPER_ENCLAVE, _is_loopback

__all__ = ["Ros2Gateway", "Ros2Unavailable", "gateway", "close_gateway", "helper_address", "ros2_present",
           "ros2_python", "when_ros2_present"]

_log = nonblocking_logger("rosout.micros_rt.services")

#: what an action sink gets when the helper is gone: ``sink(GONE, 0, {"error": words}, b"")``
GONE = 0
ACTION_EVENTS = frozenset((G_GOAL, G_CANCEL, G_ACCEPTED, G_FEEDBACK, G_RESULT))

HELPER = Path(__file__).resolve().parent / "ros2_helper.py"
#: seconds the helper may take to import rclpy and start its node
START_TIMEOUT = 20.0

_FASTDDS_LOOPBACK = """<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor><transport_id>udp_loopback</transport_id><type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList></transport_descriptor>
    <transport_descriptor><transport_id>shm_local</transport_id><type>SHM</type></transport_descriptor>
  </transport_descriptors>
  <participant profile_name="micros_rt_loopback" is_default_profile="true"><rtps>
    <userTransports><transport_id>udp_loopback</transport_id><transport_id>shm_local</transport_id></userTransports>
    <useBuiltinTransports>false</useBuiltinTransports></rtps></participant>
</profiles>
"""

#: what must not reach the helper's interpreter from a rospy process
_SCRUB_ENV = ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "ROS_PACKAGE_PATH", "ROS_PYTHON_VERSION")
#: the environment that makes a helper another (its DDS domain and discovery, its RMW and profile): processes that
#: differ in one of these get helpers of their own
_HELPER_ENV = ("ROS_DOMAIN_ID", "RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
               "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY", "ROS_SECURITY_ENABLE",
               "ROS_SECURITY_KEYSTORE", "ROS_DISABLE_LOANED_MESSAGES")


def helper_address(python: str, env: Optional[Dict[str, str]] = None) -> str:
    """The abstract Unix socket name of the helper for ``python`` and this environment: one per user, ROS 2
    environment (:data:`_HELPER_ENV`, micros_rt's loopback rule) and helper code (an edited helper is another).
    Abstract names belong to a network namespace, so each namespace host has its own.

    >>> a = helper_address("/p", {"ROS_DOMAIN_ID": "7"})
    >>> a == helper_address("/p", {"ROS_DOMAIN_ID": "7", "OTHER": "x"}), a == helper_address("/p", {"ROS_DOMAIN_ID": "8"})
    (True, False)
    """
    given: Dict[str, str] = dict(os.environ if env is None else env)
    code = hashlib.sha1()
    for path in (HELPER, Path(__file__).resolve().parent / "helper_protocol.py"):
        code.update(path.read_bytes())
    key = "\0".join([str(os.getuid()), python, str(_is_loopback(given)), code.hexdigest(),
                     *(f"{k}={given.get(k, '')}" for k in _HELPER_ENV)])
    return "micros_rt_ros2_helper_" + hashlib.sha1(key.encode()).hexdigest()[:24]


class Ros2Unavailable(MicrosRtError):
    """The ROS 2 side of services cannot work in this process (no ROS 2 Python, the helper failed); the
    message says why and what to set."""


def ros2_python(env: Optional[Dict[str, str]] = None) -> Optional[str]:
    """The Python of a ROS 2 installation: ``MICROS_RT_ROS2_PYTHON``, else a ``.venv-ros2`` beside the micros_rt
    source tree or in the working directory; None when there is none."""
    given = settings.ROS2_PYTHON.get(env)
    if given:
        return given
    for base in (Path(__file__).resolve().parents[2], Path.cwd()):
        candidate = base / ".venv-ros2" / "bin" / "python"
        if candidate.exists():
            return str(candidate)
    return None


class _Pending:
    __slots__ = ("event", "meta", "body")

    def __init__(self) -> None:
        self.event = threading.Event()
        self.meta: Dict[str, Any] = {}
        self.body = b""


#: ``handler(name, request_bytes) -> response_bytes`` for a ROS 2 client's request (raises to fail it)
Handler = Callable[[bytes], bytes]
#: ``sink(op, goal_key, meta, body)``: an action's frames from the helper, in order, on the socket's thread
ActionSink = Callable[[int, int, Dict[str, Any], bytes], None]


class Ros2Gateway:
    """This process's connection to the host's ROS 2 helper and the calls in flight through it. Thread-safe;
    ``close()`` leaves the helper."""

    def __init__(self, node_name: str, *, python: Optional[str] = None, workers: int = 4) -> None:
        python = python or ros2_python()
        if python is None:
            raise Ros2Unavailable(
                "no ROS 2 Python found for services toward ROS 2: set MICROS_RT_ROS2_PYTHON to the python of an "
                "installation with rclpy (e.g. .venv-ros2/bin/python, see docs/services.md)")
        self.python = python
        self._ids = itertools.count(1)
        self._pending: Dict[int, _Pending] = {}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._handlers: Dict[str, Handler] = {}
        self._action_sinks: Dict[str, ActionSink] = {}
        #: action frames that named no action of this process (counted, never silent)
        self.unrouted_action_frames = 0
        self._workers = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="micros_rt service")
        self.closed = False
        self._sock, self._reader, hello = self._connect(python, _ros2_node_name(node_name))
        threading.Thread(target=self._read_loop, name="micros_rt ROS 2 helper", daemon=True).start()
        _log.info("micros_rt: ROS 2 service helper reached (pid %s, %s)", hello.get("pid"), hello.get("rmw"))

    def _connect(self, python: str, node: str) -> Tuple[socket.socket, Any, Dict[str, Any]]:
        """A connection to the host's helper, and its HELLO: started first when none runs (or the one that runs is
        leaving). Ros2Unavailable when none answers within START_TIMEOUT."""
        address = helper_address(python)
        deadline = time.monotonic() + START_TIMEOUT
        started: Optional[Tuple["subprocess.Popen[bytes]", str, List[str]]] = None   # (process, its stderr file, scratch)
        why = ""
        try:
            while time.monotonic() < deadline:
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                try:
                    sock.connect("\0" + address)
                except OSError as exc:
                    sock.close()
                    why = f"cannot connect ({exc})"
                    if started is not None and started[0].poll() is not None:
                        if started[0].returncode != 0:
                            break   # it failed: its output says why
                        self._forget(started)   # another helper had the address (and may be leaving): again
                        started = None
                    if started is None:
                        started = self._start(python, address)
                    time.sleep(0.05)
                    continue
                # blocking, whatever socket.setdefaulttimeout() says (rospy sets 60 s once a subscriber connected)
                sock.settimeout(max(0.1, deadline - time.monotonic()))
                reader = sock.makefile("rb", buffering=1 << 16)
                try:
                    sock.sendall(encode(HELLO, 0, {"node": node}))
                    frame = read_frame(reader)
                except OSError as exc:
                    frame, why = None, f"no HELLO ({exc})"
                if frame is None or frame[0] != HELLO:
                    sock.close()   # the helper was leaving (its last process had gone): start or find another
                    why = why or "the helper closed the connection before its HELLO"
                    time.sleep(0.05)
                    continue
                sock.settimeout(None)
                return sock, reader, frame[2]
            if started is not None and started[0].poll() is not None:
                raise Ros2Unavailable(f"the ROS 2 service helper ({python} {HELPER.name}) exited with code "
                                      f"{started[0].returncode} at its start: {self._tail(started[1])!r}; is rclpy "
                                      f"installed there, and ROS_DOMAIN_ID valid (0-232)?")
            raise Ros2Unavailable(f"the ROS 2 service helper ({python} {HELPER.name}) did not answer within "
                                  f"{START_TIMEOUT:g} s: {why}; is rclpy installed there?")
        finally:
            if started is not None:
                self._forget(started)

    @classmethod
    def _start(cls, python: str, address: str) -> Tuple["subprocess.Popen[bytes]", str, List[str]]:
        env, scratch = cls._helper_env()
        fd, log = tempfile.mkstemp(prefix="micros_rt_ros2_helper_", suffix=".log")
        try:
            # its output in a file (Fast DDS says a fatal error on stdout and exits), unlinked once it answered
            proc = subprocess.Popen([python, str(HELPER), address, HELPER_ENCLAVE], env=env, stdin=subprocess.DEVNULL,
                                    stdout=fd, stderr=fd, close_fds=True, start_new_session=True)
        except OSError as exc:
            for path in [log, *scratch]:
                os.unlink(path)
            raise Ros2Unavailable(f"cannot start the ROS 2 service helper with {python}: {exc}") from exc
        finally:
            os.close(fd)
        # reaped here while this process runs (it outlives this process when others use it)
        threading.Thread(target=proc.wait, name="micros_rt ROS 2 helper reaper", daemon=True).start()
        return proc, log, scratch

    @staticmethod
    def _forget(started: Tuple["subprocess.Popen[bytes]", str, List[str]]) -> None:
        """The files of a helper this process started: Fast DDS has read its profile once the helper answered
        (or it is gone); its stderr stays open in it, unlinked."""
        for path in [started[1], *started[2]]:
            try:
                os.unlink(path)
            except OSError:
                pass

    @staticmethod
    def _tail(path: str) -> str:
        try:
            with open(path, "rb") as f:
                return f.read()[-600:].decode(errors="replace").strip()
        except OSError:
            return ""

    @staticmethod
    def _helper_env() -> Tuple[Dict[str, str], List[str]]:
        env = {k: v for k, v in os.environ.items() if k not in _SCRUB_ENV}
        scratch: List[str] = []
        if _is_loopback(env) and not env.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
            fd, path = tempfile.mkstemp(prefix="micros_rt_fastdds_", suffix=".xml")
            with os.fdopen(fd, "w") as f:
                f.write(_FASTDDS_LOOPBACK)
            scratch.append(path)
            env["FASTRTPS_DEFAULT_PROFILES_FILE"] = path
            env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        return env, scratch

    # -- frames -------------------------------------------------------------------------------------------------
    def _send(self, op: int, cid: int, meta: Optional[Dict[str, Any]] = None, body: bytes = b"") -> None:
        frame = encode(op, cid, meta, body)
        try:
            with self._send_lock:
                self._sock.sendall(frame)
        except OSError as exc:
            raise Ros2Unavailable(f"the ROS 2 service helper is gone ({exc})") from exc

    def _read_loop(self) -> None:
        try:
            while True:
                frame = read_frame(self._reader)
                if frame is None:
                    break
                op, cid, meta, body = frame
                if op == REQUEST:
                    self._workers.submit(self._serve, cid, meta.get("name", ""), body)
                    continue
                if op in ACTION_EVENTS:
                    self._route_action(op, cid, meta, body)
                    continue
                if op == LOG:
                    _log.warning("micros_rt ROS 2 helper: %s", meta.get("text", ""))
                    continue
                slot = self._pending.pop(cid, None)
                if slot is not None:
                    slot.meta, slot.body = meta or {"ok": True}, body
                    slot.event.set()
        except (OSError, ValueError):
            pass
        finally:
            self._fail_all("the ROS 2 service helper is closed" if self.closed else
                           "the ROS 2 service helper went away (it was stopped or died)")

    def _fail_all(self, why: str) -> None:
        with self._lock:
            pending, self._pending = self._pending, {}
            sinks, self._action_sinks = self._action_sinks, {}
        for slot in pending.values():
            slot.meta = {"ok": False, "error": why}
            slot.event.set()
        for name, sink in sinks.items():
            self._call_sink(name, sink, GONE, 0, {"name": name, "error": why}, b"")

    def _route_action(self, op: int, key: int, meta: Dict[str, Any], body: bytes) -> None:
        name = str(meta.get("name", ""))
        sink = self._action_sinks.get(name)
        if sink is None:
            self.unrouted_action_frames += 1
            if self.unrouted_action_frames == 1:
                _log.warning("micros_rt: the ROS 2 helper sent a frame (op %d) for action %s, which this process "
                             "does not offer (counted in Ros2Gateway.unrouted_action_frames)", op, name)
            return
        self._call_sink(name, sink, op, key, meta, body)

    @staticmethod
    def _call_sink(name: str, sink: ActionSink, op: int, key: int, meta: Dict[str, Any], body: bytes) -> None:
        try:
            sink(op, key, meta, body)
        except Exception as exc:  # a bridge's bug must not stop the socket's thread
            _log.error("micros_rt: action %s: handling a frame (op %d) of the ROS 2 helper failed: %s: %s",
                       name, op, type(exc).__name__, exc)

    def _serve(self, rid: int, name: str, body: bytes) -> None:
        handler = self._handlers.get(name)
        try:
            if handler is None:
                raise LookupError(f"service {name} is not advertised here")
            answer = handler(body)
        except Exception as exc:
            try:
                self._send(FAIL, rid, {"error": str(exc)})
            except Ros2Unavailable:
                pass
            return
        try:
            self._send(RESPONSE, rid, None, answer)
        except Ros2Unavailable:
            pass

    def _exchange(self, op: int, meta: Dict[str, Any], body: bytes = b"",
                  timeout: Optional[float] = None) -> _Pending:
        slot = _Pending()
        with self._lock:
            if self.closed:
                raise Ros2Unavailable("the ROS 2 service helper is closed")
            cid = next(self._ids)
            self._pending[cid] = slot
        self._send(op, cid, meta, body)
        if not slot.event.wait(timeout):
            with self._lock:
                self._pending.pop(cid, None)
            if op == CALL:
                self._send(CANCEL, cid)
            raise TimeoutError(f"no answer within {timeout:g} s")
        return slot

    def _status(self, op: int, meta: Dict[str, Any]) -> Dict[str, Any]:
        try:
            slot = self._exchange(op, meta, timeout=START_TIMEOUT)
        except TimeoutError:
            raise Ros2Unavailable(f"the ROS 2 service helper did not answer within {START_TIMEOUT:g} s") from None
        if not slot.meta.get("ok", False):
            raise Ros2Unavailable(str(slot.meta.get("error", "the ROS 2 service helper failed")))
        return slot.meta

    # -- the API the services use -------------------------------------------------------------------------------
    def advertise(self, name: str, ros2_type: str, handler: Handler) -> None:
        """Serve ROS 2 clients of ``name``: ``handler(request bytes) -> response bytes`` runs on a worker."""
        self._handlers[name] = handler
        try:
            self._status(ADVERTISE, {"name": name, "type": ros2_type})
        except Exception:
            self._handlers.pop(name, None)
            raise

    def unadvertise(self, name: str) -> None:
        self._handlers.pop(name, None)
        if not self.closed:
            try:
                self._status(UNADVERTISE, {"name": name})
            except Ros2Unavailable:
                pass

    def prepare_client(self, name: str, ros2_type: str) -> None:
        """Create the helper's client early, so that DDS discovery of the server runs before the first call."""
        self._status(CLIENT, {"name": name, "type": ros2_type})

    def server_ready(self, name: str, ros2_type: str) -> bool:
        """Whether the helper's client of ``name`` has discovered a ROS 2 server."""
        return bool(self._status(READY, {"name": name, "type": ros2_type}).get("ready"))

    def server_names(self) -> List[str]:
        """The services ROS 2 servers offer now (DDS discovery), by name, whatever their type."""
        return [str(n) for n in self._status(SERVICE_NAMES, {"name": ""}).get("names", [])]

    def call(self, name: str, ros2_type: str, request: bytes, timeout: Optional[float]) -> bytes:
        """One call to a ROS 2 server: the response's bytes. Raises TimeoutError, or ``RuntimeError`` in words."""
        slot = self._exchange(CALL, {"name": name, "type": ros2_type}, request, timeout)
        if "error" in slot.meta:
            raise RuntimeError(str(slot.meta["error"]))
        return slot.body

    # -- the API the actions use (micros_rt.actions) -------------------------------------------------------------
    def new_key(self) -> int:
        """A number for a goal sent to a ROS 2 action server, unique in this process."""
        return next(self._ids)

    def serve_action(self, name: str, ros2_type: str, sink: ActionSink) -> None:
        """Host a ROS 2 action server of ``name``: its goals and cancels reach ``sink`` (G_GOAL, G_CANCEL), which
        answers with :meth:`send_action` (A_VERDICT, A_FEEDBACK, A_DONE)."""
        self._action_sinks[name] = sink
        try:
            self._status(A_SERVE, {"name": name, "type": ros2_type})
        except Exception:
            self._action_sinks.pop(name, None)
            raise

    def action_client(self, name: str, ros2_type: str, sink: ActionSink) -> None:
        """Create the helper's ROS 2 action client of ``name``: goals go with :meth:`send_action` (A_SEND,
        A_CANCEL, A_FORGET), the server's answers reach ``sink`` (G_ACCEPTED, G_FEEDBACK, G_RESULT)."""
        self._action_sinks[name] = sink
        try:
            self._status(A_CLIENT, {"name": name, "type": ros2_type})
        except Exception:
            self._action_sinks.pop(name, None)
            raise

    def action_server_ready(self, name: str) -> bool:
        """Whether the helper's action client of ``name`` has discovered a ROS 2 action server."""
        return bool(self._status(A_READY, {"name": name}).get("ready"))

    def withdraw_action(self, name: str) -> None:
        """Stop serving or reaching ``name`` on ROS 2 (goals in flight there are aborted)."""
        self._action_sinks.pop(name, None)
        if not self.closed:
            try:
                self._status(A_UNSERVE, {"name": name})
            except Ros2Unavailable:
                pass

    def send_action(self, op: int, key: int, meta: Dict[str, Any], body: bytes = b"") -> None:
        """One frame of a goal to the helper; Ros2Unavailable when the helper is gone."""
        self._send(op, key, meta, body)

    def close(self) -> None:
        """Leave the helper (this process's ROS 2 nodes go); harmless twice."""
        if self.closed:
            return
        self.closed = True
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()   # the helper drops this process's nodes (and exits when no process is left)
        self._workers.shutdown(wait=False)
        self._fail_all("the ROS 2 service helper is closed")

    def __enter__(self) -> "Ros2Gateway":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _ros2_node_name(ros1_name: str) -> str:
    """A ROS 2 node name for the helper of ROS 1 node ``/ns/talker``: ``ns_talker_services``."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", ros1_name.strip("/")) or "micros_rt"
    if base[0].isdigit():
        base = "n" + base
    return base + "_services"


_gateway: Optional[Ros2Gateway] = None
_gateway_failed: Optional[str] = None
_gateway_lock = threading.Lock()


def gateway(node_name: str) -> Ros2Gateway:
    """The process's helper, started on first use; Ros2Unavailable (said once in the log) when it cannot be."""
    global _gateway, _gateway_failed
    with _gateway_lock:
        if _gateway is not None and not _gateway.closed:
            return _gateway
        if _gateway_failed is not None:
            raise Ros2Unavailable(_gateway_failed)
        if settings.DISABLE_ROS2_SERVICES.get():
            _gateway_failed = "services toward ROS 2 are off (MICROS_RT_DISABLE_ROS2_SERVICES is set)"
            raise Ros2Unavailable(_gateway_failed)
        try:
            _gateway = Ros2Gateway(node_name)
        except Ros2Unavailable as exc:
            _gateway_failed = str(exc)
            _log.warning("micros_rt: %s; services reach ROS 1 only", exc)
            raise
        import rospy

        rospy.on_shutdown(close_gateway)  # the helper also exits by itself when this process does
        return _gateway


def ros2_present() -> bool:
    """Whether a ROS 2 peer may be on the DDS domain now (:func:`micros_rt.transports.dds.process.ros2_on_domain`):
    under ``MICROS_RT_ROS2=auto`` no helper starts before one is, so a robot with no ROS 2 node runs none."""
    from ..transports.dds.process import ros2_on_domain

    return ros2_on_domain()


#: Seconds between looks for a ROS 2 peer on the domain while servers wait for one (a ``stat`` each)
PRESENCE_POLL = 0.5


class _WhenPresent:
    """Starts of ROS 2 sides that wait for a ROS 2 peer on the domain, run in order on one thread of the process
    once :func:`ros2_present` (the thread ends when none waits)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._waiting: List[Callable[[], None]] = []
        self._thread: Optional[threading.Thread] = None

    def run(self, start: Callable[[], None]) -> None:
        """``start()`` now when a ROS 2 peer may be there, else later, on this object's thread."""
        if ros2_present():
            start()
            return
        with self._lock:
            self._waiting.append(start)
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="micros_rt ROS 2 presence", daemon=True)
                self._thread.start()

    def cancel(self, start: Callable[[], None]) -> None:
        with self._lock:
            if start in self._waiting:
                self._waiting.remove(start)

    def _loop(self) -> None:
        import rospy

        while True:
            with self._lock:
                if not self._waiting or rospy.is_shutdown():
                    self._waiting, self._thread = [], None
                    return
            if not ros2_present():
                time.sleep(PRESENCE_POLL)
                continue
            with self._lock:
                starts, self._waiting = self._waiting, []
            _log.info("micros_rt: a ROS 2 node is on the DDS domain: starting the ROS 2 side of this process's "
                      "services")
            for start in starts:
                try:
                    start()
                except Exception:  # one server's failure must not keep the others from ROS 2
                    _log.exception("micros_rt: starting a service's ROS 2 side failed")


when_ros2_present = _WhenPresent()


def close_gateway() -> None:
    """Stop the process's helper (at shutdown)."""
    global _gateway
    with _gateway_lock:
        found, _gateway = _gateway, None
    if found is not None:
        found.close()

