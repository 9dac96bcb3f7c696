#!/usr/bin/python3
"""The stock ROS 1 side of the relay's ``ros2:`` tests, in one rospy process (/usr/bin/python3, no micros_rt).

    stock_relay_peer.py --trigger-dir DIR

Publishes ``/chatter`` (std_msgs/String, 10 Hz, "ros1 <n>"), ``/clock`` (rosgraph_msgs/Clock, 10 Hz, 1000 s +
n * 0.1 s) and the latched ``/ros1_latched`` (one message, "ros1 latched <pid>"); serves ``/set_flag`` (std_srvs/SetBool: success = data) and
``/ros1_basic`` (test_msgs/BasicTypes, a type with no ROS 1 package, built here at run time: the request echoed);
listens to ``/ros2_chatter``
(the relay's import of a ROS 2 topic). A file ``late`` in ``--trigger-dir`` (looked for every 10 ms) makes it
subscribe then to ``/ros2_latched`` and emit ``{"event": "late", "data", "after_ms"}`` for each message, with the
time from creating the subscriber to it. Other events: ``ready``, ``recv`` for the first 20 messages of
``/ros2_chatter``, ``served`` per call.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import rospy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from std_srvs.srv import SetBool, SetBoolResponse

from ros1_srv_types import fields, srv_class


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}, default=str) + "\n")
    sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trigger-dir", required=True)
    ap.add_argument("--duration", type=float, default=120.0)
    args = ap.parse_args()
    rospy.init_node(f"stock_relay_peer_{os.getpid()}", disable_rosout=True, disable_signals=False)
    chatter = rospy.Publisher("/chatter", String, queue_size=10)
    clock = rospy.Publisher("/clock", Clock, queue_size=10)
    latched = rospy.Publisher("/ros1_latched", String, queue_size=1, latch=True)
    latched.publish(String(data=f"ros1 latched {os.getpid()}"))
    heard = [0]

    def on_ros2(msg: Any) -> None:
        heard[0] += 1
        if heard[0] <= 20:
            emit("recv", topic="/ros2_chatter", data=msg.data)

    rospy.Subscriber("/ros2_chatter", String, on_ros2)

    def on_set(req: Any) -> Any:
        emit("served", name="/set_flag", data=req.data)
        return SetBoolResponse(success=req.data, message=f"rospy {os.getpid()} got {req.data}")

    rospy.Service("/set_flag", SetBool, on_set)
    # test_msgs/BasicTypes has no ROS 1 package: its class built from the same definition as ROS 2's
    basic_srv = srv_class("test_msgs/BasicTypes")

    def on_basic(req: Any) -> Any:
        emit("served", name="/ros1_basic")
        return basic_srv._response_class(**fields(req))

    rospy.Service("/ros1_basic", basic_srv, on_basic)
    start = [0.0]

    def on_late(msg: Any) -> None:
        emit("late", data=msg.data, after_ms=(time.monotonic() - start[0]) * 1e3)

    emit("ready", pid=os.getpid())
    late_path = os.path.join(args.trigger_dir, "late")
    subscribed = False
    deadline = time.monotonic() + args.duration
    n = 0
    next_send = time.monotonic()
    while not rospy.is_shutdown() and time.monotonic() < deadline:
        now = time.monotonic()
        if now >= next_send:
            chatter.publish(String(data=f"ros1 {n}"))
            clock.publish(Clock(clock=rospy.Time(1000 + n // 10, (n % 10) * 100_000_000)))
            n += 1
            next_send += 0.1
        if not subscribed and os.path.exists(late_path):
            subscribed = True
            start[0] = time.monotonic()
            rospy.Subscriber("/ros2_latched", String, on_late)
        time.sleep(0.01)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (KeyboardInterrupt, rospy.ROSInterruptException):
        sys.exit(0)
