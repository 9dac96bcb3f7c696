"""micros_rt's ROS 2 service helper: the rclpy side of a micros_rt process's services.

Run by :mod:`micros_rt.services.gateway` with the Python of a ROS 2 installation (rclpy with its RMW, Fast DDS
in Jazzy), never inside the rospy process: ``python ros2_helper.py ADDRESS ENCLAVE``. One helper serves every
micros_rt process of the host that has the same user, DDS domain and ROS 2 environment (issue 42: one DDS
participant for the host's services and actions, not one per process). It listens on the abstract Unix socket
``ADDRESS`` (a name per network namespace; a second helper of the same name cannot bind it and exits). Each
connection is one micros_rt process: its first frame (HELLO) names its node, and the helper gives it an rclpy node of
its own in the one rclpy context (so ``ros2 node list`` shows one node per process, all in one participant). When a
process closes its end (it exits or dies), its node goes; when none is left for IDLE_EXIT s, the helper exits.
It imports nothing of micros_rt or ROS 1 but ``helper_protocol.py`` beside it (standard library only). Imported
as part of the package (beside rospy, without rclpy) it defines its names and runs nothing.

What the helper has to say about one process's services or actions goes to that process as a LOG frame (it logs
it); its own stderr is a file the first process unlinks once the helper is up.

Why a helper and not Cyclone in the micros_rt process (docs/services.md): ROS 2's Fast DDS RMW identifies a
request by its RTPS sample identity and answers with a ``related_sample_identity`` inline QoS parameter, and a
Fast DDS client drops every reply without one that names it (rmw_fastrtps_shared_cpp/src/rmw_response.cpp,
``__rmw_take_response``). Cyclone DDS (11.0.1) writes no such parameter and passes none it receives to the
application, so a Cyclone participant can neither answer a Fast DDS client nor tell which reply is its own.

Frames, both ways: :mod:`micros_rt.services.helper_protocol` (the one table of op codes both sides import).

Actions (:mod:`micros_rt.actions`) live on a second node, ``<node>_actions``, spun by a multi-threaded executor of
their own: an action server's execute callback holds a thread for its goal's life (rclpy 7's executor polls a
coroutine that awaits a future in a busy loop, so goals do not await), and the service node keeps its single thread.
"""

from __future__ import annotations

import importlib
import itertools
import json
import os
import queue
import re
import signal
import socket
import sys
import threading
import time
import warnings
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Tuple

try:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.serialization import deserialize_message, serialize_message
    from rclpy.signals import SignalHandlerOptions
except ImportError:
    if not __package__:
        raise  # run as the helper: rclpy is what it is for
    # imported as micros_rt.services.ros2_helper beside rospy (the package's doctests, the protocol's test): its
    # names and op codes, nothing that runs

if __package__:
    from .helper_protocol import (A_CANCEL, A_CLIENT, A_DONE, A_FEEDBACK, A_FORGET, A_READY, A_SEND, A_SERVE,
                                  A_UNSERVE, A_VERDICT, ADVERTISE, CALL, CANCEL, CLIENT, ERROR, FAIL, G_ACCEPTED,
                                  G_CANCEL, G_FEEDBACK, G_GOAL, G_RESULT, HELLO, LOG, READY, REQUEST, RESPONSE,
                                  RESULT, SERVICE_NAMES, STATUS, UNADVERTISE, encode, read_frame)
else:  # run as a script by the ROS 2 interpreter: its own directory is sys.path[0]
    from helper_protocol import (A_CANCEL, A_CLIENT, A_DONE, A_FEEDBACK, A_FORGET,  # type: ignore[import-not-found,no-redef]
                                 A_READY, A_SEND, A_SERVE, A_UNSERVE, A_VERDICT, ADVERTISE, CALL, CANCEL, CLIENT, ERROR,
                                 FAIL, G_ACCEPTED, G_CANCEL, G_FEEDBACK, G_GOAL, G_RESULT, HELLO, LOG, READY,
                                 REQUEST, RESPONSE, RESULT, SERVICE_NAMES, STATUS, UNADVERTISE, encode,
                                 read_frame)
#: ops about goals in flight: handled on the socket's thread (setting up and tearing down go through the executor)
_GOAL_OPS = (A_VERDICT, A_FEEDBACK, A_DONE, A_SEND, A_CANCEL, A_FORGET)
#: action_msgs/GoalStatus codes
_SUCCEEDED, _CANCELED, _ABORTED = 4, 5, 6
#: threads of the actions' executor: each goal a ROS 2 client has running on a ROS 1 server holds one
ACTION_THREADS = 64
#: goals of ROS 2 clients at once per process; more are rejected, so that threads stay free for cancels
MAX_SERVED_GOALS = ACTION_THREADS - 4
#: seconds between the last feedback published and the result: a client that takes both in one batch handles the
#: result first and drops the feedback after it (rclpy's ActionClient does)
FEEDBACK_GRACE = 0.02
#: depth of the feedback publisher of served actions and of the feedback reader of reached ones (rclpy's default
#: is 10): a burst of feedback, or an executor behind under load, does not overwrite feedback not yet taken
FEEDBACK_DEPTH = 1000

#: how often pending calls are checked for a server that went away
_WATCH_PERIOD = 0.2
#: seconds the helper stays with no process connected before it exits (a process restarting finds it there)
IDLE_EXIT = 5.0
#: seconds of one spin of the helper's main thread (it looks for its end between them)
SPIN_SLICE = 0.5
#: a response Fast DDS would not send (the client's response reader not yet matched by this helper's writer) is
#: tried again every RESEND_PERIOD s for RESEND_FOR s; then it is counted lost and said
RESEND_PERIOD = 0.05
RESEND_FOR = 10.0
#: rclpy 7 (Jazzy) makes a response the RMW did not send a RuntimeWarning, not an error (service_send_response):
#: rmw_fastrtps waits 100 ms for the writer to match the client's reader and then gives up, "client will not
#: receive response". A client that found the server can still be unknown to it: discovery is two-sided and, under
#: load, the server's side comes later. The warning is caught here (per thread) and the response sent again.
_SEND_TIMEOUT = "failed to send response (timeout)"
_unsent = threading.local()


def _catch_send_timeouts() -> None:
    """Route rclpy's "failed to send response (timeout)" warnings to the thread that sent (``_unsent.hit``)
    instead of stderr; every one of them, not only the first of its line (Python's default)."""
    shown = warnings.showwarning

    def showwarning(message: Any, category: Any, filename: str, lineno: int, file: Any = None,
                    line: Optional[str] = None) -> None:
        if issubclass(category, RuntimeWarning) and str(message).startswith(_SEND_TIMEOUT):
            _unsent.hit = True
            return
        shown(message, category, filename, lineno, file, line)

    warnings.filterwarnings("always", message=re.escape(_SEND_TIMEOUT), category=RuntimeWarning)
    warnings.showwarning = showwarning


#: id(rclpy ActionServer handle) -> what says words to the process that offers it (Helper.say)
_ACTION_OWNERS: Dict[int, Callable[[str], None]] = {}


def _say_to_stderr(text: str) -> None:
    try:
        sys.stderr.write(f"micros_rt ROS 2 helper: {text}\n")
    except (OSError, ValueError):
        pass


def _resend_action_responses() -> None:
    """rclpy's ActionServer sends its goal, cancel and result responses inside rclpy (action/server.py), with the
    same warning when Fast DDS gives up on them: its three senders go through the resender too (this process has
    no other action servers than micros_rt's). Done once per helper."""
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    if getattr(_rclpy.ActionServer, "_micros_rt_resends", False):
        return
    _rclpy.ActionServer._micros_rt_resends = True
    for method in ("send_goal_response", "send_cancel_response", "send_result_response"):
        original = getattr(_rclpy.ActionServer, method)
        what = method[len("send_"):].replace("_", " ")

        def patched(handle: Any, header: Any, response: Any, original: Any = original, what: str = what) -> None:
            def send(response: Any, header: Any) -> None:
                original(handle, header, response)
            if not send_or_timed_out(send, response, header):
                RESENDER.put(f"an action's {what}", send, response, header,
                             _ACTION_OWNERS.get(id(handle), _say_to_stderr))

        setattr(_rclpy.ActionServer, method, patched)


def send_or_timed_out(send: Any, response: Any, header: Any) -> bool:
    """Send one response; False when the RMW gave up on it (the client's reader not matched yet)."""
    _unsent.hit = False
    send(response, header)
    return not _unsent.hit


def srv_class(ros2_type: str) -> Any:
    """``pkg/srv/Name`` (or ``pkg/action/Name``) -> the rclpy class; ImportError/AttributeError in words when it
    is missing."""
    pkg, kind, name = ros2_type.split("/")
    what = "action" if kind == "action" else "service"
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ImportError as exc:
        raise ImportError(f"the ROS 2 package {pkg!r} is not installed for {sys.executable} "
                          f"(needed for the {what} type {ros2_type})") from exc
    try:
        return getattr(module, name)
    except AttributeError:
        raise AttributeError(f"the ROS 2 package {pkg!r} has no {what} type {name!r} ({ros2_type})") from None


class Helper:
    """One micros_rt process's services and actions: its rclpy node (and ``<node>_actions`` once it has actions)
    in the helper's one rclpy context, its frames on its connection."""

    def __init__(self, sock: socket.socket, reader: Any, node_name: str, executor: Any) -> None:
        self.sock = sock
        self.reader = reader
        self.executor = executor
        self.send_lock = threading.Lock()
        self.node = rclpy.create_node(node_name)
        self.inbox: Deque[Tuple[int, int, Dict[str, Any], bytes]] = deque()
        self.wake = self.node.create_guard_condition(self.drain)
        self.services: Dict[str, Any] = {}
        self.clients: Dict[str, Tuple[Any, Any]] = {}                 # name -> (rclpy client, srv class)
        self.calls: Dict[int, Tuple[str, Any, Any]] = {}              # call id -> (name, client, future)
        self.served: Dict[int, Dict[str, Any]] = {}                   # request id -> what answers it
        self.served_lock = threading.Lock()
        self.by_response: Dict[int, int] = {}                         # id(response object) -> request id
        self.next_request = 1
        self.node.create_timer(_WATCH_PERIOD, self.watch)
        self.node_name = node_name
        self._actions: Optional["Actions"] = None
        executor.add_node(self.node)

    def say(self, text: str) -> None:
        """Words for this process's log (a LOG frame; stderr once the process is gone)."""
        if self.sock.fileno() < 0:
            _say_to_stderr(text)
            return
        self.send(LOG, 0, {"text": text})

    # -- frames -----------------------------------------------------------------------------------------------
    def send(self, op: int, cid: int, meta: Optional[Dict[str, Any]] = None, body: bytes = b"") -> None:
        frame = encode(op, cid, meta, body)
        with self.send_lock:
            try:
                self.sock.sendall(frame)
            except OSError:
                pass  # micros_rt went away: the reader sees the end and stops the helper

    def read_loop(self) -> None:
        """The process's frames until it closes its end (it exits or dies); then its nodes go."""
        try:
            while True:
                frame = read_frame(self.reader)
                if frame is None:
                    break
                op, cid, meta, body = frame
                if op in (RESPONSE, FAIL):
                    self.answer(op, cid, meta, body)  # no executor needed: send_response is thread-safe
                elif op in _GOAL_OPS:
                    try:
                        self.actions().goal_op(op, cid, meta, body)
                    except Exception as exc:  # the socket's thread must go on
                        self.say(f"a goal's frame (op {op}) failed: {exc}")
                else:
                    self.inbox.append((op, cid, meta, body))
                    self.wake.trigger()
        except (OSError, ValueError):
            pass
        finally:
            self.close()

    def close(self) -> None:
        """The process is gone: its actions, services, clients and node go (the helper goes on for others)."""
        try:
            self.sock.close()
        except OSError:
            pass
        self.close_actions()
        try:
            self.executor.remove_node(self.node)
            self.node.destroy_node()
        except Exception as exc:   # the helper is shutting down itself
            _say_to_stderr(f"removing the node {self.node_name} failed: {exc}")

    def drain(self) -> None:
        while self.inbox:
            op, cid, meta, body = self.inbox.popleft()
            try:
                self.handle(op, cid, meta, body)
            except Exception as exc:  # every failure goes back in words, the helper keeps running
                self.send(ERROR if op == CALL else STATUS, cid, {"ok": False, "error": f"{exc}"})

    def handle(self, op: int, cid: int, meta: Dict[str, Any], body: bytes) -> None:
        name = meta.get("name", "")
        if op == ADVERTISE:
            if name not in self.services:
                cls = srv_class(meta["type"])
                srv = self.node.create_service(cls, name, self.request_callback(name, cls))
                srv.send_response = self.deferred_sender(srv)  # the answer comes later, from micros_rt
                self.services[name] = srv
            self.send(STATUS, cid, {"ok": True})
        elif op == UNADVERTISE:
            srv = self.services.pop(name, None)
            if srv is not None:
                self.node.destroy_service(srv)
            self.send(STATUS, cid, {"ok": True})
        elif op == CLIENT:
            self.client(name, meta["type"])
            self.send(STATUS, cid, {"ok": True})
        elif op == READY:
            client, _ = self.client(name, meta["type"])
            self.send(STATUS, cid, {"ok": True, "ready": bool(client.service_is_ready())})
        elif op == CALL:
            client, cls = self.client(name, meta["type"])
            if not client.service_is_ready():
                self.send(ERROR, cid, {"error": f"no ROS 2 server of {name} is available (none discovered on "
                                                f"ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')})"})
                return
            try:
                request = deserialize_message(body, cls.Request)
            except Exception as exc:
                self.send(ERROR, cid, {"error": f"the request does not fit the ROS 2 type {meta['type']} "
                                                f"Request: {exc}"})
                return
            future = client.call_async(request)
            self.calls[cid] = (name, client, future)
            future.add_done_callback(lambda f, cid=cid: self.call_done(cid, f))
        elif op == CANCEL:
            found = self.calls.pop(cid, None)
            if found is not None:
                found[1].remove_pending_request(found[2])
        elif op == SERVICE_NAMES:
            # servers only (count_services), not this helper's own clients
            names = sorted(n for n, _types in self.node.get_service_names_and_types() if self.node.count_services(n))
            self.send(STATUS, cid, {"ok": True, "names": names})
        elif op == A_SERVE:
            self.actions().serve(name, meta["type"])
            self.send(STATUS, cid, {"ok": True})
        elif op == A_CLIENT:
            self.actions().client(name, meta["type"])
            self.send(STATUS, cid, {"ok": True})
        elif op == A_READY:
            found_client = self.actions().clients.get(name)
            self.send(STATUS, cid, {"ok": True, "ready": bool(found_client and found_client[0].server_is_ready())})
        elif op == A_UNSERVE:
            self.actions().withdraw(name)
            self.send(STATUS, cid, {"ok": True})

    def actions(self) -> "Actions":
        """The actions' node and executor, created on first use."""
        with self.served_lock:
            if self._actions is None:
                base = self.node_name[: -len("_services")] if self.node_name.endswith("_services") else self.node_name
                self._actions = Actions(self, base + "_actions")
            return self._actions

    def close_actions(self) -> None:
        if self._actions is not None:
            self._actions.close()

    def client(self, name: str, ros2_type: str) -> Tuple[Any, Any]:
        found = self.clients.get(name)
        if found is None:
            cls = srv_class(ros2_type)
            found = self.clients[name] = (self.node.create_client(cls, name), cls)
        return found

    def call_done(self, cid: int, future: Any) -> None:
        if self.calls.pop(cid, None) is None:
            return  # cancelled (timed out on the micros_rt side)
        try:
            self.send(RESULT, cid, None, serialize_message(future.result()))
        except Exception as exc:
            self.send(ERROR, cid, {"error": f"the ROS 2 call failed: {exc}"})

    def watch(self) -> None:
        """Fail calls whose server went away (discovery lost it), rather than leaving them to time out."""
        for cid, (name, client, future) in list(self.calls.items()):
            if not future.done() and not client.service_is_ready():
                self.calls.pop(cid, None)
                client.remove_pending_request(future)
                self.send(ERROR, cid, {"error": f"the ROS 2 server of {name} went away during the call"})

    # -- serving ROS 2 clients ------------------------------------------------------------------------------
    def request_callback(self, name: str, cls: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            with self.served_lock:
                rid = self.next_request
                self.next_request += 1
                self.served[rid] = {"cls": cls, "name": name, "header": None, "body": None, "t": time.monotonic()}
                self.by_response[id(response)] = rid
            self.send(REQUEST, rid, {"name": name}, serialize_message(request))
            return response
        return callback

    def deferred_sender(self, srv: Any) -> Any:
        """rclpy sends the callback's return value with the request's header at once; here the header is kept
        until micros_rt's handler answered (the handler runs in the micros_rt process, not on this executor)."""
        original = srv.send_response

        def send_response(response: Any, header: Any) -> None:
            with self.served_lock:
                rid = self.by_response.pop(id(response), None)
                slot = self.served.get(rid) if rid is not None else None
                if rid is None or slot is None:
                    return
                slot["send"] = original
                if slot["body"] is None:
                    slot["header"] = header
                    return
                del self.served[rid]  # micros_rt answered first
            self.reply(slot, original, header)
        return send_response

    def answer(self, op: int, rid: int, meta: Dict[str, Any], body: bytes) -> None:
        with self.served_lock:
            slot = self.served.get(rid)
            if slot is None:
                return
            if op == FAIL:  # ROS 2 has no error reply: the client's own timeout tells it
                del self.served[rid]
                return
            if slot["header"] is None:
                slot["body"] = body
                return
            del self.served[rid]
        self.reply(slot, slot["send"], slot["header"], body)

    def reply(self, slot: Dict[str, Any], send: Any, header: Any, body: Optional[bytes] = None) -> None:
        try:
            response = deserialize_message(body if body is not None else slot["body"], slot["cls"].Response)
            if not send_or_timed_out(send, response, header):
                RESENDER.put(f"a response of {slot['name']}", send, response, header, self.say)
        except Exception as exc:
            self.say(f"cannot send a response of {slot['name']}: {exc}")


class Resender:
    """Responses the RMW did not send yet (their client's reader not matched), sent again on a thread of their own
    every RESEND_PERIOD s until it takes them or RESEND_FOR s passed; those are counted (``lost``) and said to the
    process they are of."""

    def __init__(self, period: float = RESEND_PERIOD, give_up_after: float = RESEND_FOR) -> None:
        self.period, self.give_up_after = period, give_up_after
        self.pending: "queue.Queue[Tuple[float, str, Any, Any, Any, Callable[[str], None]]]" = queue.Queue()
        self.resent = 0   # responses that went out on a later try
        self.lost = 0
        self._thread: Optional[threading.Thread] = None
        self._lock = threading.Lock()

    def put(self, what: str, send: Any, response: Any, header: Any,
            say: Callable[[str], None] = _say_to_stderr) -> None:
        """``what``: the response in words ("a response of /robot/set_mode"); ``say``: where words about it go."""
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="micros_rt resend", daemon=True)
                self._thread.start()
        self.pending.put((time.monotonic() + self.give_up_after, what, send, response, header, say))

    def _run(self) -> None:
        while True:
            item = self.pending.get()
            waiting = [item]
            while True:   # everything that waits, tried together each period
                time.sleep(self.period)
                while not self.pending.empty():
                    waiting.append(self.pending.get_nowait())
                waiting = [w for w in waiting if not self._try(*w)]
                if not waiting:
                    break

    def _try(self, deadline: float, what: str, send: Any, response: Any, header: Any,
             say: Callable[[str], None]) -> bool:
        """True when the item is done with: sent, or given up on."""
        try:
            if send_or_timed_out(send, response, header):
                self.resent += 1
                return True
        except Exception as exc:
            self.lost += 1
            say(f"cannot send {what}: {exc}")
            return True
        if time.monotonic() < deadline:
            return False
        self.lost += 1
        say(f"{what} is lost ({self.lost} so far): the ROS 2 client's response reader was not discovered by the "
            f"helper within {self.give_up_after:.0f} s (its request was)")
        return True


#: the helper's one resender (its responses are of every process it serves)
RESENDER = Resender()


class _Served:
    """A ROS 2 client's goal on a ROS 1 server: the verdict micros_rt gives, then feedback and result, in order."""

    __slots__ = ("name", "verdict", "accepted", "items", "handle")

    def __init__(self, name: str) -> None:
        self.name = name
        self.verdict = threading.Event()
        self.accepted = False
        self.items: "queue.Queue[Tuple[int, int, bytes]]" = queue.Queue()   # (op, status, body)
        self.handle: Any = None


class _Sent:
    """A ROS 1 client's goal on a ROS 2 server (micros_rt's key): the rclpy goal handle once accepted."""

    __slots__ = ("name", "client", "handle", "cancel_requested")

    def __init__(self, name: str, client: Any) -> None:
        self.name = name
        self.client = client
        self.handle: Any = None
        self.cancel_requested = False


class Actions:
    """The helper's actions, on a node of their own (``<node>_actions``) and a multi-threaded executor.

    Served (a ROS 1 server offered to ROS 2 clients): an rclpy ActionServer; its goal callback sends the goal to
    micros_rt (G_GOAL) and waits for the ROS 1 server's verdict (A_VERDICT); its execute callback publishes the
    feedback micros_rt forwards (A_FEEDBACK) until the result (A_DONE); a cancel goes to micros_rt (G_CANCEL).
    Reached (a ROS 2 server offered to ROS 1 clients): an rclpy ActionClient; micros_rt's goals (A_SEND) go out and
    the answers come back (G_ACCEPTED, G_FEEDBACK, G_RESULT). Client work runs in one exclusive callback group, so a
    goal's response is never taken before its future is registered (rclpy's ActionClient has no lock for that).
    """

    def __init__(self, helper: Helper, node_name: str) -> None:
        # imported here: a process that uses services only does not pay for them
        from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
        from rclpy.executors import MultiThreadedExecutor
        from rclpy.qos import QoSProfile

        _resend_action_responses()
        self.ActionClient, self.ActionServer, self.QoSProfile = ActionClient, ActionServer, QoSProfile
        self.CancelResponse, self.GoalResponse = CancelResponse, GoalResponse
        self.helper = helper
        self.node = rclpy.create_node(node_name)
        self.serve_group = ReentrantCallbackGroup()
        self.client_group = MutuallyExclusiveCallbackGroup()
        self.lock = threading.Lock()
        self.servers: Dict[str, Any] = {}
        self.clients: Dict[str, Tuple[Any, Any]] = {}          # name -> (rclpy ActionClient, action class)
        self.keys = itertools.count(1)
        self.served: Dict[int, _Served] = {}                   # helper's key -> goal of a ROS 2 client
        self.by_request: Dict[int, int] = {}                   # id(goal request message) -> helper's key
        self.sent: Dict[int, _Sent] = {}                       # micros_rt's key -> goal on a ROS 2 server
        self.waiting: Dict[int, Tuple[str, bytes]] = {}        # micros_rt's key -> goal for a server not yet found
        self.client_inbox: Deque[Tuple[int, int, Dict[str, Any], bytes]] = deque()
        self.client_wake = self.node.create_guard_condition(self.drain_clients, callback_group=self.client_group)
        self.node.create_timer(_WATCH_PERIOD, self.watch, callback_group=self.client_group)
        self.dropped = 0
        self.executor = MultiThreadedExecutor(num_threads=ACTION_THREADS)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.spin, name="micros_rt actions", daemon=True)
        self.thread.start()

    def spin(self) -> None:
        while True:
            try:
                self.executor.spin()
                return
            except (KeyboardInterrupt, ExternalShutdownException):
                return
            except Exception as exc:
                # a callback's exception leaves rclpy's spin (e.g. rclpy's ActionServer raises "Failed to send goal
                # response" when Fast DDS gave up on a client's reader not yet discovered): that one exchange is
                # lost, the client's own timeout tells it; the actions go on
                if not rclpy.ok():
                    return
                self.drop(f"an action exchange rclpy failed on ({exc})")

    def close(self) -> None:
        for slot in list(self.served.values()):
            slot.verdict.set()
            slot.items.put((A_DONE, _ABORTED, b""))
        for server in self.servers.values():
            _ACTION_OWNERS.pop(id(server._handle), None)
        self.executor.shutdown(timeout_sec=1.0)
        # the spinning thread must be out of rclpy before the node goes and the process exits (else a C++
        # std::terminate at exit, seen when the helper closed right after the actions' node started)
        self.thread.join(timeout=2.0)
        self.node.destroy_node()

    def drop(self, what: str) -> None:
        self.dropped += 1
        if self.dropped == 1 or self.dropped % 100 == 0:
            self.helper.say(f"dropped {what} ({self.dropped} action frames dropped so far)")

    # -- set-up (on the service node's executor thread) ---------------------------------------------------------
    def serve(self, name: str, ros2_type: str) -> None:
        if name in self.servers:
            return
        cls = srv_class(ros2_type)
        self.servers[name] = self.ActionServer(
            self.node, cls, name, execute_callback=lambda handle: self.execute(name, cls, handle),
            goal_callback=lambda request: self.on_goal(name, request),
            cancel_callback=lambda handle: self.on_cancel(name, handle),
            callback_group=self.serve_group, feedback_pub_qos_profile=self.QoSProfile(depth=FEEDBACK_DEPTH))
        _ACTION_OWNERS[id(self.servers[name]._handle)] = self.helper.say

    def client(self, name: str, ros2_type: str) -> Tuple[Any, Any]:
        found = self.clients.get(name)
        if found is None:
            cls = srv_class(ros2_type)
            client = self.ActionClient(self.node, cls, name, callback_group=self.client_group,
                                       feedback_sub_qos_profile=self.QoSProfile(depth=FEEDBACK_DEPTH))
            found = self.clients[name] = (client, cls)
        return found

    def withdraw(self, name: str) -> None:
        server = self.servers.pop(name, None)
        if server is not None:
            for slot in [g for g in self.served.values() if g.name == name]:
                slot.verdict.set()
                slot.items.put((A_DONE, _ABORTED, b""))
            _ACTION_OWNERS.pop(id(server._handle), None)
            server.destroy()
        client = self.clients.pop(name, None)
        if client is not None:
            for key in [k for k, g in self.sent.items() if g.name == name]:
                self.sent.pop(key, None)
            client[0].destroy()

    # -- frames about goals (on the socket's thread) ------------------------------------------------------------
    def goal_op(self, op: int, key: int, meta: Dict[str, Any], body: bytes) -> None:
        if op in (A_SEND, A_CANCEL, A_FORGET):
            self.client_inbox.append((op, key, meta, body))
            self.client_wake.trigger()
            return
        slot = self.served.get(key)
        if slot is None:
            self.drop(f"{'feedback' if op == A_FEEDBACK else 'an answer'} for a goal that is over (key {key})")
            return
        if op == A_VERDICT:
            slot.accepted = bool(meta.get("accepted"))
            slot.verdict.set()
        else:
            slot.items.put((op, int(meta.get("status", _ABORTED)), body))

    # -- serving ROS 2 clients (executor threads; a goal's callbacks may block) --------------------------------
    def on_goal(self, name: str, request: Any) -> Any:
        key = next(self.keys)
        slot = _Served(name)
        with self.lock:
            if len(self.served) >= MAX_SERVED_GOALS:
                self.helper.say(f"a ROS 2 client's goal of {name} is rejected: {MAX_SERVED_GOALS} goals of ROS 2 "
                                f"clients are running already in this process")
                return self.GoalResponse.REJECT
            self.served[key] = slot
            self.by_request[id(request)] = key   # the goal handle keeps this very message as its request
        self.helper.send(G_GOAL, key, {"name": name}, serialize_message(request))
        while not slot.verdict.wait(0.5):        # micros_rt answers within its accept_timeout
            if not rclpy.ok():
                break
        if slot.accepted:
            return self.GoalResponse.ACCEPT
        with self.lock:
            self.served.pop(key, None)
            self.by_request.pop(id(request), None)
        return self.GoalResponse.REJECT

    def on_cancel(self, name: str, handle: Any) -> Any:
        key = self.by_request.get(id(handle.request))
        if key is None:
            return self.CancelResponse.REJECT
        self.helper.send(G_CANCEL, key, {"name": name})
        return self.CancelResponse.ACCEPT

    def execute(self, name: str, cls: Any, handle: Any) -> Any:
        key = self.by_request.get(id(handle.request))
        slot = self.served.get(key) if key is not None else None
        last_feedback = 0.0
        try:
            while slot is not None:
                try:
                    op, status, body = slot.items.get(timeout=0.5)
                except queue.Empty:
                    if rclpy.ok():
                        continue
                    break
                if op == A_FEEDBACK:
                    try:
                        handle.publish_feedback(deserialize_message(body, cls.Feedback))
                        last_feedback = time.monotonic()
                    except Exception as exc:
                        self.drop(f"a feedback of {name} that does not fit {cls.__name__}.Feedback ({exc})")
                    continue
                wait = last_feedback + FEEDBACK_GRACE - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                try:
                    result = deserialize_message(body, cls.Result) if body else cls.Result()
                except Exception as exc:
                    self.helper.say(f"the result of a goal of {name} does not fit {cls.__name__}.Result ({exc}); the "
                                    f"goal ends aborted")
                    result, status = cls.Result(), _ABORTED
                if status == _SUCCEEDED:
                    handle.succeed()
                elif status == _CANCELED and handle.is_cancel_requested:
                    handle.canceled()
                else:
                    handle.abort()   # ROS 2 cannot cancel a goal nobody asked to cancel: it ends aborted
                return result
            handle.abort()
            return cls.Result()
        finally:
            with self.lock:
                if key is not None:
                    self.served.pop(key, None)
                self.by_request.pop(id(handle.request), None)

    # -- reaching ROS 2 servers (the client group: one thread at a time) ----------------------------------------
    def drain_clients(self) -> None:
        while self.client_inbox:
            op, key, meta, body = self.client_inbox.popleft()
            name = str(meta.get("name", ""))
            try:
                if op == A_SEND:
                    self.send_goal(key, name, body)
                elif op == A_CANCEL:
                    slot = self.sent.get(key)
                    if slot is not None and slot.handle is not None:
                        slot.handle.cancel_goal_async()
                    elif slot is not None:
                        slot.cancel_requested = True   # cancelled as soon as it is accepted
                elif op == A_FORGET:                   # micros_rt gave up waiting for the goal response
                    self.waiting.pop(key, None)
                    slot = self.sent.pop(key, None)
                    if slot is not None and slot.handle is not None:
                        slot.handle.cancel_goal_async()
            except Exception as exc:
                self.helper.send(G_RESULT, key, {"name": name, "status": _ABORTED,
                                                 "error": f"the ROS 2 helper failed on the goal: {exc}"})

    def send_goal(self, key: int, name: str, body: bytes) -> None:
        found = self.clients.get(name)
        if found is None:
            raise LookupError(f"no ROS 2 action client of {name} in the helper")
        client, cls = found
        if not client.server_is_ready():
            self.waiting[key] = (name, body)   # sent once discovery finds the server; micros_rt bounds the wait
            return
        try:
            goal = deserialize_message(body, cls.Goal)
        except Exception as exc:
            self.helper.send(G_ACCEPTED, key, {"name": name, "accepted": False, "error": (
                f"the goal does not fit the ROS 2 type {cls.__module__.split('.')[0]}/action/{cls.__name__} "
                f"Goal: {exc}")})
            return
        slot = self.sent[key] = _Sent(name, client)

        def feedback(message: Any) -> None:
            self.helper.send(G_FEEDBACK, key, {"name": name}, serialize_message(message.feedback))

        future = client.send_goal_async(goal, feedback_callback=feedback)
        future.add_done_callback(lambda f: self.goal_answered(key, slot, f))

    def goal_answered(self, key: int, slot: _Sent, future: Any) -> None:
        handle = future.result()
        if self.sent.get(key) is not slot:          # forgotten (micros_rt stopped waiting): do not leave it running
            if handle is not None and handle.accepted:
                handle.cancel_goal_async()
            return
        if handle is None or not handle.accepted:
            self.sent.pop(key, None)
            self.helper.send(G_ACCEPTED, key, {"name": slot.name, "accepted": False,
                                               "error": f"the ROS 2 action server of {slot.name} rejected the goal"})
            return
        slot.handle = handle
        self.helper.send(G_ACCEPTED, key, {"name": slot.name, "accepted": True})
        if slot.cancel_requested:
            handle.cancel_goal_async()
        handle.get_result_async().add_done_callback(lambda f: self.result_done(key, slot, f))

    def result_done(self, key: int, slot: _Sent, future: Any) -> None:
        if self.sent.pop(key, None) is None:
            return
        response = future.result()
        self.helper.send(G_RESULT, key, {"name": slot.name, "status": int(response.status)},
                         serialize_message(response.result))

    def watch(self) -> None:
        """Send goals whose server discovery has found since; end goals whose ROS 2 server went away (discovery
        lost it), rather than leaving them to hang."""
        for key, (name, body) in list(self.waiting.items()):
            found = self.clients.get(name)
            if found is None or found[0].server_is_ready():
                self.waiting.pop(key, None)
                try:
                    self.send_goal(key, name, body)
                except Exception as exc:
                    self.helper.send(G_RESULT, key, {"name": name, "status": _ABORTED,
                                                     "error": f"the ROS 2 helper failed on the goal: {exc}"})
        gone: List[Tuple[int, _Sent]] = [(k, g) for k, g in list(self.sent.items()) if not g.client.server_is_ready()]
        for key, slot in gone:
            if self.sent.pop(key, None) is not None:
                self.helper.send(G_RESULT, key, {"name": slot.name, "status": _ABORTED, "error": (
                    f"the ROS 2 action server of {slot.name} went away during the goal")})


class Host:
    """The helper's listening socket and the processes connected to it; the helper exits IDLE_EXIT s after the
    last one left (or after START_GRACE s when none came)."""

    #: seconds a helper waits for its first process (the one that started it connects within START_TIMEOUT)
    START_GRACE = 30.0

    def __init__(self, listener: socket.socket, executor: Any) -> None:
        self.listener, self.executor = listener, executor
        self.lock = threading.Lock()
        self.connected = 0
        self.closing = False
        self.helpers: List[Helper] = []
        #: set to end the helper: idle, or SIGTERM/SIGINT
        self.stop = threading.Event()

    def accept_loop(self) -> None:
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return   # closed: the helper is on its way out
            threading.Thread(target=self.serve, args=(conn,), name="micros_rt process", daemon=True).start()

    def serve(self, conn: socket.socket) -> None:
        """One process: its HELLO (its node's name), then its frames until it closes its end."""
        conn.setblocking(True)
        with self.lock:
            if self.closing:
                conn.close()   # it connects again and starts a new helper
                return
            self.connected += 1
        helper: Optional[Helper] = None
        try:
            reader = conn.makefile("rb", buffering=1 << 16)
            frame = read_frame(reader)
            if frame is None or frame[0] != HELLO:
                return
            helper = Helper(conn, reader, str(frame[2].get("node") or "micros_rt_services"), self.executor)
            with self.lock:
                self.helpers.append(helper)
            helper.send(HELLO, frame[1], {"pid": os.getpid(), "rmw": rclpy.get_rmw_implementation_identifier()})
            helper.read_loop()   # closes the helper (its nodes) at the end
        except Exception as exc:   # one process's failure must not stop the others'
            _say_to_stderr(f"a process's connection failed: {type(exc).__name__}: {exc}")
        finally:
            conn.close()
            with self.lock:
                if helper is not None and helper in self.helpers:
                    self.helpers.remove(helper)
                self.connected -= 1
                if self.connected == 0:
                    self.exit_later(IDLE_EXIT)

    def exit_later(self, seconds: float) -> None:
        timer = threading.Timer(seconds, self.exit_if_idle)
        timer.daemon = True
        timer.start()

    def exit_if_idle(self) -> None:
        with self.lock:
            if self.connected or self.closing:
                return
            self.closing = True
        self.listener.close()   # a process that comes now starts a new helper
        self.stop.set()         # the main thread's spin ends


def main() -> None:
    address = sys.argv[1]
    # the enclave rmw writes in the participant's user data ("enclave=/micros_rt;"): by it the host's ROS 2 watcher
    # (micros_rt/transports/dds/watch.py) knows this participant as micros_rt's, not a ROS 2 node's
    enclave = sys.argv[2] if len(sys.argv) > 2 else "/"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind("\0" + address)   # abstract: no file, gone with the process, one per network namespace
    except OSError:
        return   # a helper of this name runs already: the processes use that one
    listener.listen(128)
    # no rclpy signal handlers: a SIGTERM left rclpy's spin with no node waiting forever (seen: a helper nobody had
    # connected to, still there 28 min after `timeout` sent it SIGTERM). The main thread spins in slices instead and
    # ends cleanly on SIGTERM/SIGINT (its own session: a Ctrl-C of a node's terminal does not reach it)
    rclpy.init(args=["--ros-args", "--enclave", enclave], signal_handler_options=SignalHandlerOptions.NO)
    _catch_send_timeouts()
    executor = SingleThreadedExecutor()
    host = Host(listener, executor)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: host.stop.set())
    threading.Thread(target=host.accept_loop, name="micros_rt accept", daemon=True).start()
    host.exit_later(Host.START_GRACE)
    try:
        while not host.stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=SPIN_SLICE)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # a clean shutdown lets Fast DDS remove its shared-memory segments (/dev/shm/fastrtps_*); os._exit is the
        # fallback if that hangs
        fallback = threading.Timer(3.0, os._exit, args=(0,))
        fallback.daemon = True
        fallback.start()
        try:
            listener.close()
        except OSError:
            pass
        for helper in list(host.helpers):
            helper.close_actions()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
