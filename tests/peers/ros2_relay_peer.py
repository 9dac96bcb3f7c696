"""The ROS 2 side of the relay's ``ros2:`` tests, in one rclpy process. Run ONLY with .venv-ros2/bin/python.

    ros2_relay_peer.py --prefix /r2x --trigger-dir DIR

Publishes ``/ros2_chatter`` (std_msgs/String, 10 Hz, "ros2 <n>"), ``/ros2_latched`` from two transient_local
writers (keep_last 1, one message each: "ros2 latched <pid>" and "ros2 latched 2 <pid>", as two static transform
broadcasters) and ``/r2_custom`` (test_msgs/BasicTypes, which ROS 1 has no package of: :data:`BASIC`, 5 Hz);
serves ``/ros2_trigger`` (std_srvs/Trigger) and ``/r2_basic`` (test_msgs/srv/BasicTypes: the request echoed); listens to
``/chatter`` and ``/clock`` (the relay's exports of a stock ROS 1 node's topics). Every name has ``--prefix`` in
front. Commands come as files in ``--trigger-dir`` (the test writes them when it is ready; the peer looks every
10 ms):

- ``late``: subscribe now, transient_local (depth 100, as tf2 reads ``/tf_static``), to ``/ros1_latched``; emits
  ``{"event": "late", "data", "after_ms"}`` for each message
  with the time from creating the subscription to its first message;
- ``call``: JSON ``{"name", "count", "data"}``: calls std_srvs/SetBool ``name`` ``count`` times; emits
  ``{"event": "called", "ok", "p50_ms", "last"}``;
- ``call_basic``: JSON ``{"name", "fields"}``: calls test_msgs/srv/BasicTypes ``name`` once; emits
  ``{"event": "called_basic", "fields"}`` (the response's, ``byte_value`` as a number) or ``error``.

Other events: ``ready``; ``recv`` for each of the first 20 messages on ``/chatter`` (then only counted, in
``heard`` every second, with the publisher counts of ``/ros2_chatter`` and ``/chatter`` ROS 2 sees); ``clock`` (``sec``, ``nanosec``) for the first 3 on ``/clock``; ``served`` per Trigger
call.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from typing import Any, List

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from test_msgs.msg import BasicTypes
from test_msgs.srv import BasicTypes as BasicTypesSrv


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}, default=str) + "\n")
    sys.stdout.flush()


LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /r2_custom's message: each field at an edge of its type (``byte_value``: ROS 2's byte is an octet)
BASIC = {"bool_value": True, "byte_value": 200, "char_value": 100, "float32_value": 1.5, "float64_value": -2.25e300,
         "int8_value": -128, "uint8_value": 255, "int16_value": -32768, "uint16_value": 65535,
         "int32_value": -2 ** 31, "uint32_value": 2 ** 32 - 1, "int64_value": -2 ** 63, "uint64_value": 2 ** 64 - 1}


def basic(cls: Any, fields: Any) -> Any:
    return cls(**{k: bytes([v]) if k == "byte_value" else v for k, v in fields.items()})


def fields_of(msg: Any) -> Any:
    return {k: (getattr(msg, k)[0] if k == "byte_value" else getattr(msg, k)) for k in msg.get_fields_and_field_types()}


LATE_JOINER = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--prefix", default="")
    ap.add_argument("--trigger-dir", required=True)
    ap.add_argument("--duration", type=float, default=120.0)
    args = ap.parse_args()
    p = args.prefix
    rclpy.init()
    node = rclpy.create_node(f"ros2_relay_peer_{os.getpid()}")
    chatter = node.create_publisher(String, f"{p}/ros2_chatter", 10)
    latched = node.create_publisher(String, f"{p}/ros2_latched", LATCHED)
    latched.publish(String(data=f"ros2 latched {os.getpid()}"))
    latched2 = node.create_publisher(String, f"{p}/ros2_latched", LATCHED)   # a second writer of the topic
    latched2.publish(String(data=f"ros2 latched 2 {os.getpid()}"))
    custom = node.create_publisher(BasicTypes, f"{p}/r2_custom", 10)
    node.create_timer(0.2, lambda: custom.publish(basic(BasicTypes, BASIC)))

    def on_basic(request: Any, response: Any) -> Any:
        emit("served", name=f"{p}/r2_basic")
        return basic(BasicTypesSrv.Response, fields_of(request))

    node.create_service(BasicTypesSrv, f"{p}/r2_basic", on_basic)
    heard: List[str] = []

    def on_chatter(msg: Any) -> None:
        heard.append(msg.data)
        if len(heard) <= 20:
            emit("recv", topic=f"{p}/chatter", data=msg.data)

    node.create_subscription(String, f"{p}/chatter", on_chatter, 10)
    clocks: List[Any] = []

    def on_clock(msg: Any) -> None:
        clocks.append(msg)
        if len(clocks) <= 3:
            emit("clock", sec=msg.clock.sec, nanosec=msg.clock.nanosec)

    node.create_subscription(Clock, f"{p}/clock", on_clock, 10)

    def on_trigger(_request: Any, response: Any) -> Any:
        emit("served", name=f"{p}/ros2_trigger")
        response.success, response.message = True, f"rclpy {os.getpid()} triggered"
        return response

    node.create_service(Trigger, f"{p}/ros2_trigger", on_trigger)
    seq = [0]

    def tick() -> None:
        chatter.publish(String(data=f"ros2 {seq[0]}"))
        seq[0] += 1

    node.create_timer(0.1, tick)
    executor = MultiThreadedExecutor(num_threads=3)
    executor.add_node(node)
    stop = threading.Event()

    def commands() -> None:
        done = set()
        last_heard = time.monotonic()
        while not stop.is_set():
            for name in ("late", "call", "call_basic"):
                path = os.path.join(args.trigger_dir, name)
                if name in done or not os.path.exists(path):
                    continue
                done.add(name)
                if name == "late":
                    got = threading.Event()
                    start = time.monotonic()

                    def on_late(msg: Any, start: float = start) -> None:
                        emit("late", data=msg.data, after_ms=(time.monotonic() - start) * 1e3)

                    # as tf2's listener of /tf_static: deep enough for every publisher's latched message
                    node.create_subscription(String, f"{p}/ros1_latched", on_late, LATE_JOINER)
                elif name == "call_basic":
                    with open(path, encoding="utf-8") as f:
                        plan = json.load(f)
                    basic_client = node.create_client(BasicTypesSrv, plan["name"])
                    if not basic_client.wait_for_service(timeout_sec=15.0):
                        emit("called_basic", error="no server discovered within 15 s")
                        continue
                    future = basic_client.call_async(basic(BasicTypesSrv.Request, plan["fields"]))
                    finished = threading.Event()
                    future.add_done_callback(lambda _f, e=finished: e.set())
                    finished.wait(15.0)
                    if future.done() and future.result() is not None:
                        emit("called_basic", fields=fields_of(future.result()))
                    else:
                        emit("called_basic", error="no answer within 15 s")
                else:
                    with open(path, encoding="utf-8") as f:
                        plan = json.load(f)
                    client = node.create_client(SetBool, plan["name"])
                    if not client.wait_for_service(timeout_sec=15.0):
                        emit("called", ok=0, error="no server discovered within 15 s")
                        continue
                    times, last = [], None
                    for i in range(int(plan.get("count", 1))):
                        t0 = time.perf_counter()
                        future = client.call_async(SetBool.Request(data=bool(plan.get("data", True))))
                        finished = threading.Event()
                        future.add_done_callback(lambda _f, e=finished: e.set())
                        finished.wait(10.0)
                        if future.done() and future.result() is not None:
                            times.append(time.perf_counter() - t0)
                            res = future.result()
                            last = {"success": res.success, "message": res.message}
                        else:
                            client.remove_pending_request(future)
                    times.sort()
                    emit("called", ok=len(times), p50_ms=times[len(times) // 2] * 1e3 if times else None, last=last)
            if time.monotonic() - last_heard > 1.0:
                last_heard = time.monotonic()
                # publishers of /ros2_chatter ROS 2 sees: this node only (the relay's ROS 1 copy stays off DDS)
                emit("heard", n=len(heard), ros2_chatter_publishers=node.count_publishers(f"{p}/ros2_chatter"),
                     chatter_publishers=node.count_publishers(f"{p}/chatter"))
            stop.wait(0.01)

    threading.Thread(target=commands, daemon=True).start()
    emit("ready", pid=os.getpid())
    deadline = time.monotonic() + args.duration
    try:
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop.set()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
