"""A ROS 1 service server or client: stock rospy (/usr/bin/python3, no micros_rt) or micros_rt's NodeHandle
(project venv, ``--impl micros_rt``: ``advertise_service``/``service_client``, which reach ROS 2 too).

    ros1_service_peer.py --impl rospy serve --services '[{"name": "/r1/set_bool", "type": "std_srvs/SetBool",
                                                          "mode": "fail"}]' --seconds 60
    ros1_service_peer.py --impl micros_rt call --plan '[{"name": "/r2/set_bool", "type": "std_srvs/SetBool",
                                                         "args": {"data": true}, "count": 100, "timeout": 2}]'

Server modes: "normal"; "fail" (SetBool raises for False); "slow" (answers after 30 s). Events (JSON lines):
serve: {"event": "ready", "ros2": [...names served to ROS 2 too]}, {"event": "served", "name"} per request unless
--quiet. call, per step: {"event": "calling", "label"}, then for one call {"event": "response", "fields"} or
{"event": "error", "kind", "message", "elapsed"}; for count > 1 {"event": "summary", "ok", "errors", "p50_us",
"p99_us", "last"}; finally {"event": "done"}. A step's "request_type" (a message type) sends a message of that
type instead, "args" fills it. "threads": N splits "count" among N threads calling one client at once,
each with its own test_msgs/BasicTypes request; "echo_check" counts responses that differ from the request
("mismatches": answers to another caller's request).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from typing import Any, Dict, List

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import rospy  # noqa: E402

from ros1_srv_types import answer, fields, msg_class, srv_class  # noqa: E402


def emit(event: str, **kw: Any) -> None:
    # one write per line: a log line from another thread must not land inside it
    sys.stdout.write(json.dumps({"event": event, **kw}, default=repr) + "\n")
    sys.stdout.flush()


def serve(args: argparse.Namespace) -> None:
    specs: List[Dict[str, Any]] = json.loads(args.services)
    nh = None
    if args.impl == "micros_rt":
        import micros_rt
        micros_rt.init_node("mrt_service_server", anonymous=True)
        nh = micros_rt.NodeHandle()
    else:
        rospy.init_node("stock_service_server", anonymous=True)
    handles, ros2, waiting = [], [], []
    for spec in specs:
        cls, name, mode = srv_class(spec["type"]), spec["name"], spec.get("mode", "normal")
        who = f"{args.impl} {name}" + ("!" if mode == "fail" else "")

        def handler(request: Any, cls: Any = cls, name: str = name, who: str = who, mode: str = mode,
                    srv_type: str = spec["type"]) -> Any:
            if not args.quiet:
                emit("served", name=name)
            if mode == "slow":
                time.sleep(30)
            return answer(who, srv_type, request, cls._response_class)

        if nh is not None:
            server = nh.advertise_service(name, cls, handler)
            if server.serves_ros2 or server.ros2_waiting:  # waiting: for a ROS 2 node on the domain (auto)
                ros2.append(name)
                if server.ros2_waiting:
                    waiting.append(name)
            else:
                emit("ros2_error", name=name, error=server.ros2_error)
            handles.append(server)
        else:
            handles.append(rospy.Service(name, cls, handler))
    emit("ready", ros2=ros2, waiting=waiting)
    end = time.monotonic() + args.seconds
    while not rospy.is_shutdown() and time.monotonic() < end:
        time.sleep(0.1)
    emit("done")


def percentile(values: List[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def call(args: argparse.Namespace) -> None:
    plan: List[Dict[str, Any]] = json.loads(args.plan)
    nh = None
    if args.impl == "micros_rt":
        import micros_rt
        micros_rt.init_node("mrt_service_client", anonymous=True)
        nh = micros_rt.NodeHandle()
    else:
        rospy.init_node("stock_service_client", anonymous=True)
    clients: Dict[Any, Any] = {}
    for step in plan:
        label = step.get("label", step["name"])
        cls = srv_class(step["type"])
        key = (step["name"], step["type"], step.get("timeout"))
        if key not in clients:
            clients[key] = (nh.service_client(step["name"], cls, timeout=step.get("timeout")) if nh is not None
                            else rospy.ServiceProxy(step["name"], cls))
        client = clients[key]
        if step.get("wait"):
            t0 = time.monotonic()
            try:
                if nh is not None:
                    client.wait_for_service(step["wait"])
                else:
                    rospy.wait_for_service(step["name"], step["wait"])
                emit("available", label=label, elapsed=time.monotonic() - t0)
            except Exception as exc:
                emit("unavailable", label=label, kind=type(exc).__name__, message=str(exc),
                     elapsed=time.monotonic() - t0)
                continue
        if "request_type" in step:
            request = msg_class(step["request_type"])(**step.get("args", {}))
        else:
            request = cls._request_class(**step.get("args", {}))
        emit("calling", label=label)
        count = int(step.get("count", 1))
        times: List[float] = []
        errors: List[str] = []
        last: Any = None
        mismatches = [0]

        def run(n: int, request: Any) -> None:
            nonlocal last
            for _ in range(n):
                t0 = time.perf_counter()
                try:
                    last = fields(client(request))
                    times.append(time.perf_counter() - t0)
                    if step.get("echo_check") and last != fields(request):
                        mismatches[0] += 1  # an answer to another caller's request
                except Exception as exc:
                    elapsed = time.perf_counter() - t0
                    if count == 1:
                        emit("error", label=label, kind=type(exc).__name__, message=str(exc), elapsed=elapsed,
                             side=getattr(client, "side", None))
                    errors.append(f"{type(exc).__name__}: {exc}")

        threads = int(step.get("threads", 1))
        if threads == 1:
            run(count, request)
        else:  # concurrent callers of one client, each with a request of its own (string_value + its index)
            workers = []
            for i in range(threads):
                own = cls._request_class(**{**step.get("args", {}),
                                            "string_value": f"{step['args']['string_value']} {i}"})
                workers.append(threading.Thread(target=run, args=(count // threads, own)))
            for w in workers:
                w.start()
            for w in workers:
                w.join()
        if count == 1:
            if last is not None:
                emit("response", label=label, fields=last, elapsed=times[0], side=getattr(client, "side", None))
        else:
            emit("summary", label=label, ok=len(times), errors=errors[:3], n_errors=len(errors),
                 p50_us=percentile(times, 0.5) * 1e6, p99_us=percentile(times, 0.99) * 1e6, last=last,
                 side=getattr(client, "side", None), mismatches=mismatches[0])
    emit("done")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--impl", choices=("rospy", "micros_rt"), default="rospy")
    sub = parser.add_subparsers(dest="mode", required=True)
    s = sub.add_parser("serve")
    s.add_argument("--services", required=True)
    s.add_argument("--seconds", type=float, default=120.0)
    s.add_argument("--quiet", action="store_true")
    c = sub.add_parser("call")
    c.add_argument("--plan", required=True)
    args = parser.parse_args()
    (serve if args.mode == "serve" else call)(args)


if __name__ == "__main__":
    main()
