#!/usr/bin/python3
"""A plain rospy listener: rospy only, no micros_rt import, no test helpers.

Runs as a stock node (``/usr/bin/python3 plain_listener.py``) and unchanged under ``micros-rt run``
(and from a launch file). Subscribes to ``std_msgs/String`` on ``chatter`` (relative: remappings and
namespaces apply) with ``callback_args``. Prints JSON lines: ``ready``, ``recv`` per message (data,
transport from the connection header: ``DDS`` under micros_rt, else TCPROS), ``done`` (received).
Options: --count N (0: no limit), --duration S, --queue-size N, --tcp-nodelay.
"""

import argparse
import json
import os
import sys
import threading
import time
from typing import Any, List

import rospy
from std_msgs.msg import String


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps(dict(event=event, **fields)) + "\n")
    sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--topic", default="chatter")
    ap.add_argument("--count", type=int, default=0)
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--queue-size", type=int, default=1000)
    ap.add_argument("--tcp-nodelay", action="store_true")
    args = ap.parse_args(rospy.myargv()[1:])

    rospy.init_node("plain_listener")
    lock = threading.Lock()
    received = [0]

    def callback(msg: Any, tag: str) -> None:
        header = getattr(msg, "_connection_header", None) or {}
        with lock:
            received[0] += 1
        emit("recv", data=msg.data, transport=header.get("transport", "TCPROS"), callerid=header.get("callerid"),
             tag=tag, node=rospy.get_name())

    sub = rospy.Subscriber(args.topic, String, callback, callback_args="plain", queue_size=args.queue_size,
                           tcp_nodelay=args.tcp_nodelay)
    emit("ready", node=rospy.get_name(), topic=sub.resolved_name, pid=os.getpid(), uri=rospy.get_node_uri(),
         is_rospy_subscriber=isinstance(sub, rospy.Subscriber))
    end = time.monotonic() + args.duration
    while not rospy.is_shutdown() and time.monotonic() < end and (args.count == 0 or received[0] < args.count):
        time.sleep(0.05)
    emit("done", received=received[0])


if __name__ == "__main__":
    main()
