"""ROS 2 (rclpy, Fast DDS) service server or client for tests. Run ONLY with .venv-ros2/bin/python.

    ros2_service_peer.py serve --services '[{"name": "/r2/set_bool", "type": "std_srvs/srv/SetBool"}]'
    ros2_service_peer.py call --plan '[{"name": "/mrt/set_bool", "type": "std_srvs/srv/SetBool",
                                        "args": {"data": true}, "count": 100, "timeout": 2, "wait": 10}]'

A step's "response_durability": "transient_local" makes a client no server can answer (its response reader
matches no volatile writer; it calls once the service is listed). A step's "start_at" (time.time() value) holds its calls until then; "echo_check" (for an echoing server, test_msgs/BasicTypes) counts responses that differ from the request in
the summary's "mismatches". The same server modes and events as tests/peers/ros1_service_peer.py ("silent": never answers; "fail": SetBool
raises for False, which in rclpy ends the server's spin, so it is not used here). Environment as ros2_peer.py
(loopback-only Fast DDS, this run's ROS_DOMAIN_ID).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import os
import threading
import time
from typing import Any, Dict, List

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


#: set when the peer stops: a "silent" callback returns then, so that the process exits cleanly (Fast DDS
#: removes its shared-memory segments only then)
STOP = threading.Event()


def emit(event: str, **kw: Any) -> None:
    # one write per line: a log line from another thread must not land inside it
    sys.stdout.write(json.dumps({"event": event, **kw}, default=repr) + "\n")
    sys.stdout.flush()


def srv_class(name: str) -> Any:
    pkg, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), cls)


def plain(value: Any) -> Any:
    if isinstance(value, bytes) and len(value) == 1:
        return value[0]     # byte (octet) is bytes of one in rclpy, an int in ROS 1
    return value


def fields(msg: Any) -> Dict[str, Any]:
    return {k: plain(getattr(msg, k)) for k in msg.get_fields_and_field_types()}


def fill(msg: Any, values: Dict[str, Any]) -> Any:
    for k, v in values.items():
        if k == "byte_value":
            v = bytes([v])
        setattr(msg, k, v)
    return msg


def serve(args: argparse.Namespace, node: Any) -> None:
    specs: List[Dict[str, Any]] = json.loads(args.services)
    for spec in specs:
        cls, name, mode = srv_class(spec["type"]), spec["name"], spec.get("mode", "normal")

        def callback(request: Any, response: Any, name: str = name, mode: str = mode, srv_type: str = spec["type"]) -> Any:
            if not args.quiet:
                emit("served", name=name)
            if mode == "silent":
                STOP.wait(3600)
            if srv_type == "std_srvs/srv/SetBool":
                response.success, response.message = request.data, f"rclpy {name} got {request.data}"
            elif srv_type == "std_srvs/srv/Trigger":
                response.success, response.message = True, f"rclpy {name} triggered"
            else:
                for k in request.get_fields_and_field_types():
                    setattr(response, k, getattr(request, k))
            return response

        # a silent service blocks its own callback group only
        node.create_service(cls, name, callback, callback_group=MutuallyExclusiveCallbackGroup())
    emit("ready")


def percentile(values: List[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def call(args: argparse.Namespace, node: Any, executor: Any) -> None:
    for step in json.loads(args.plan):
        label = step.get("label", step["name"])
        cls = srv_class(step["type"])
        if step.get("response_durability") == "transient_local":
            # a response reader no server's (volatile) writer matches: the server gets the requests and can
            # never answer; the client is never "ready", so it calls once the service is in the graph
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            client = node.create_client(cls, step["name"], qos_profile=qos)
        else:
            client = node.create_client(cls, step["name"])
        t0 = time.monotonic()
        if "response_durability" in step:
            def listed() -> bool:
                return step["name"] in dict(node.get_service_names_and_types())
            while not listed() and time.monotonic() - t0 < step.get("wait", 10.0):
                time.sleep(0.05)
            if not listed():
                emit("unavailable", label=label, elapsed=time.monotonic() - t0)
                continue
        elif not client.wait_for_service(timeout_sec=step.get("wait", 10.0)):
            emit("unavailable", label=label, elapsed=time.monotonic() - t0)
            continue
        emit("available", label=label, elapsed=time.monotonic() - t0)
        request = fill(cls.Request(), step.get("args", {}))
        if "start_at" in step:  # several peers start calling together (wall clock, seconds since the epoch)
            time.sleep(max(0.0, float(step["start_at"]) - time.time()))
        emit("calling", label=label)
        times: List[float] = []
        errors: List[str] = []
        last = None
        count = int(step.get("count", 1))
        mismatches = 0
        failed_at: List[int] = []
        for i in range(count):
            t0 = time.perf_counter()
            future = client.call_async(request)
            done = threading.Event()
            future.add_done_callback(lambda _f: done.set())
            done.wait(step.get("timeout") or 10.0)
            if future.done() and future.result() is not None:
                times.append(time.perf_counter() - t0)
                last = fields(future.result())
                if step.get("echo_check") and last != fields(request):
                    mismatches += 1  # an answer to another caller's request
            else:
                client.remove_pending_request(future)
                errors.append(f"no response within {step.get('timeout') or 10.0} s")
                failed_at.append(i)
        if count == 1:
            if last is not None:
                emit("response", label=label, fields=last, elapsed=times[0])
            else:
                emit("error", label=label, kind="Timeout", message=errors[0])
        else:
            emit("summary", label=label, ok=len(times), errors=errors[:3], n_errors=len(errors),
                 p50_us=percentile(times, 0.5) * 1e6, p99_us=percentile(times, 0.99) * 1e6, last=last,
                 mismatches=mismatches, failed_at=failed_at[:10])
    emit("done")


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="mode", required=True)
    s = sub.add_parser("serve")
    s.add_argument("--services", required=True)
    s.add_argument("--seconds", type=float, default=120.0)
    s.add_argument("--quiet", action="store_true")
    c = sub.add_parser("call")
    c.add_argument("--plan", required=True)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node(f"ros2_service_{args.mode}_{os.getpid()}")
    # callbacks on several threads (a "silent" server callback blocks only itself); a client's calls are made
    # from a worker thread and wait for their future's done callback: rclpy's spin_until_future_complete took
    # ~50 ms per call here (p50 of 1,000 calls against ~2 ms this way)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    finished = threading.Event()

    def work() -> None:
        try:
            if args.mode == "serve":
                serve(args, node)
                STOP.wait(args.seconds)
                emit("done")
            else:
                call(args, node, executor)
        finally:
            finished.set()

    # the executor spins in the main thread: a clean exit there lets Fast DDS remove its /dev/shm segments
    threading.Thread(target=work, daemon=True).start()
    try:
        while not finished.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        STOP.set()  # a "silent" callback returns now
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()

if __name__ == "__main__":
    main()
