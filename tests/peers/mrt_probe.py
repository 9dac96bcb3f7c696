"""A micros_rt node that reports on itself, for robustness tests; one JSON object per stdout line.

    mrt_probe.py listen --topic /t [--type std_msgs/String] [--duration 60]
        subscribes and prints {"event": "status", received, delivered, malformed, writers, rss_kb, threads,
        fds, transports} every 0.5 s, and {"event": "recv", "data": ...} per String message.
    mrt_probe.py churn --cycles 1000
        advertise/unregister and subscribe/unregister over distinct topics; prints {"event": "state", ...}
        (threads, fds, DDS entities, rss_kb) at the start, after 100 cycles (warm) and at the end.
    mrt_probe.py restarts --topic /t --count 100
        advertises, waits until a subscriber is matched, publishes one message, unregisters; repeats.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import threading
import time
from typing import Any, Dict, List

import roslib.message

import micros_rt


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields, default=str) + "\n")
    sys.stdout.flush()


def rss_kb() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


def process_state() -> Dict[str, int]:
    from micros_rt.cyclone import import_cyclonedds

    import_cyclonedds()   # the one locked first import: the node's threads may be importing it now
    from cyclonedds.core import Entity

    gc.collect()  # rospy leaves an epoll object per closed topic to the garbage collector

    return {"threads": threading.active_count(), "tasks": len(os.listdir("/proc/self/task")),
            "fds": len(os.listdir("/proc/self/fd")), "entities": len(Entity._entities), "rss_kb": rss_kb()}


def listen(a: argparse.Namespace, nh: micros_rt.NodeHandle) -> None:
    cls = roslib.message.get_message_class(a.type)

    def cb(msg: Any) -> None:
        if a.type == "std_msgs/String":
            emit("recv", data=msg.data)

    sub = nh.subscribe(a.topic, cls, cb, None)
    emit("ready")
    end = time.monotonic() + a.duration
    while time.monotonic() < end and not micros_rt.is_shutdown():
        s = sub.statistics()
        emit("status", received=s.received, delivered=s.delivered, malformed=s.malformed, writers=s.writers,
             transports=sub.connection_transports(), **process_state())
        time.sleep(0.5)


def churn(a: argparse.Namespace, nh: micros_rt.NodeHandle) -> None:
    from std_msgs.msg import String

    keep = nh.advertise("churn_kept", String, 10)  # the participant and its threads exist from here on
    time.sleep(1.0)
    emit("state", at="start", **process_state())
    for i in range(a.cycles):
        nh.advertise(f"churn/pub_{i}", String, 10).unregister()
        nh.subscribe(f"churn/sub_{i}", String, lambda m: None, 10).unregister()
        if i + 1 == 100:
            emit("state", at="warm", **process_state())
    time.sleep(1.0)
    emit("state", at="end", **process_state())
    keep.unregister()


def restarts(a: argparse.Namespace, nh: micros_rt.NodeHandle) -> None:
    from std_msgs.msg import String

    for i in range(a.count):
        pub = nh.advertise(a.topic, String, 10)
        deadline = time.monotonic() + 10.0
        while pub.get_num_connections() < 1 and time.monotonic() < deadline:
            time.sleep(0.005)
        pub.publish(String(data=f"restart {i}"))
        time.sleep(0.05)
        pub.unregister()
        emit("restarted", i=i)
    emit("done")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["listen", "churn", "restarts"])
    ap.add_argument("--topic", default="/probe")
    ap.add_argument("--type", default="std_msgs/String")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--cycles", type=int, default=1000)
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--node-name", default=None)
    a = ap.parse_args()
    micros_rt.init_node(a.node_name or f"mrt_probe_{a.mode}", anonymous=a.node_name is None, disable_signals=False)
    nh = micros_rt.NodeHandle()
    {"listen": listen, "churn": churn, "restarts": restarts}[a.mode](a, nh)
    micros_rt.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
