"""micros_rt's ROS 2 service helper: the rclpy side of a micros_rt process's services.

Run by :mod:`micros_rt.services.gateway` with the Python of a ROS 2 installation (rclpy with its RMW, Fast DDS
in Jazzy), never inside the rospy process: ``python ros2_helper.py FD NODE_NAME``. ``FD`` is one end of a Unix
socket pair whose other end is the micros_rt process; when that end closes (the process exits or dies), the
helper exits. It imports nothing of micros_rt or ROS 1.

Why a helper and not Cyclone in the micros_rt process (docs/services.md): ROS 2's Fast DDS RMW identifies a
request by its RTPS sample identity and answers with a ``related_sample_identity`` inline QoS parameter, and a
Fast DDS client drops every reply without one that names it (rmw_fastrtps_shared_cpp/src/rmw_response.cpp,
``__rmw_take_response``). Cyclone DDS (11.0.1) writes no such parameter and passes none it receives to the
application, so a Cyclone participant can neither answer a Fast DDS client nor tell which reply is its own.

Frames, both ways: ``<I`` length of the rest, ``<BIH`` op, call id, meta length, then the meta (UTF-8 JSON)
and a binary body (a serialized ROS 2 message, CDR with its encapsulation header).
"""

from __future__ import annotations

import importlib
import json
import os
import socket
import struct
import sys
import threading
import time
from collections import deque
from typing import Any, Deque, Dict, Optional, Tuple

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.serialization import deserialize_message, serialize_message

# micros_rt -> helper
ADVERTISE, UNADVERTISE, CLIENT, READY, CALL, CANCEL, RESPONSE, FAIL = 1, 2, 3, 4, 5, 6, 7, 8
# helper -> micros_rt
STATUS, RESULT, ERROR, REQUEST, HELLO = 20, 21, 22, 23, 24

_HEAD = struct.Struct("<IBIH")
#: how often pending calls are checked for a server that went away
_WATCH_PERIOD = 0.2


def srv_class(ros2_type: str) -> Any:
    """``pkg/srv/Name`` -> the rclpy service class; ImportError/AttributeError in words when it is missing."""
    pkg, kind, name = ros2_type.split("/")
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ImportError as exc:
        raise ImportError(f"the ROS 2 package {pkg!r} is not installed for {sys.executable} "
                          f"(needed for the service type {ros2_type})") from exc
    try:
        return getattr(module, name)
    except AttributeError:
        raise AttributeError(f"the ROS 2 package {pkg!r} has no service type {name!r} ({ros2_type})") from None


class Helper:
    def __init__(self, sock: socket.socket, node_name: str) -> None:
        self.sock = sock
        self.reader = sock.makefile("rb", buffering=1 << 16)
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

    # -- frames -----------------------------------------------------------------------------------------------
    def send(self, op: int, cid: int, meta: Optional[Dict[str, Any]] = None, body: bytes = b"") -> None:
        raw = json.dumps(meta).encode() if meta else b""
        frame = _HEAD.pack(_HEAD.size - 4 + len(raw) + len(body), op, cid, len(raw)) + raw + body
        with self.send_lock:
            try:
                self.sock.sendall(frame)
            except OSError:
                pass  # micros_rt went away: the reader sees the end and stops the helper

    def read_loop(self) -> None:
        try:
            while True:
                head = self.reader.read(_HEAD.size)
                if len(head) < _HEAD.size:
                    break
                length, op, cid, meta_len = _HEAD.unpack(head)
                rest = self.reader.read(length - (_HEAD.size - 4))
                meta = json.loads(rest[:meta_len]) if meta_len else {}
                body = rest[meta_len:]
                if op in (RESPONSE, FAIL):
                    self.answer(op, cid, meta, body)  # no executor needed: send_response is thread-safe
                else:
                    self.inbox.append((op, cid, meta, body))
                    self.wake.trigger()
        finally:
            # micros_rt closed its end: nothing left to serve. A clean shutdown lets Fast DDS remove its
            # shared-memory segments (/dev/shm/fastrtps_*); os._exit is the fallback if that hangs.
            fallback = threading.Timer(3.0, os._exit, args=(0,))
            fallback.daemon = True
            fallback.start()
            rclpy.try_shutdown()

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
                self.served[rid] = {"cls": cls, "header": None, "body": None, "t": time.monotonic()}
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
            send(response, header)
        except Exception as exc:
            sys.stderr.write(f"micros_rt ROS 2 helper: cannot send a response: {exc}\n")


def main() -> None:
    fd, node_name = int(sys.argv[1]), sys.argv[2]
    sock = socket.socket(fileno=fd)
    rclpy.init(args=[])
    helper = Helper(sock, node_name)
    executor = SingleThreadedExecutor()
    executor.add_node(helper.node)
    threading.Thread(target=helper.read_loop, name="micros_rt socket", daemon=True).start()
    helper.send(HELLO, 0, {"pid": os.getpid(), "rmw": rclpy.get_rmw_implementation_identifier()})
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown(timeout_sec=1.0)
        helper.node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
