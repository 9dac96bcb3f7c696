#!/usr/bin/env python3
"""A micros_rt talker that a ROS 2 (rclpy) node hears directly: no bridge process.

micros_rt publishes std_msgs/String on /chatter; on DDS that is topic ``rt/chatter`` with type
``std_msgs::msg::dds_::String_``, exactly what a ROS 2 node subscribed to ``/chatter`` looks for.
It sends ``--count`` messages (default 20, at 2 Hz) and exits by itself. Like any volatile DDS
publisher, messages sent before the ROS 2 subscriber has been discovered are not delivered to it: even with the
listener started first, discovery takes about 1.5 s from this node's start, so the listener's first message is
"hello ROS 2 3" or so (docs/ros2.md, section 3, shows a run).

Terminal 1 (ROS 1 master; micros_rt nodes still register with it):

    roscore

Terminal 2 (the ROS 2 listener, rclpy venv; never run rclpy in the rospy venv):

    export ROS_DOMAIN_ID=42 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \\
           FASTRTPS_DEFAULT_PROFILES_FILE=$PWD/tests/peers/fastdds_loopback.xml
    .venv-ros2/bin/python tests/peers/ros2_peer.py listen --topic /chatter --count 10

Terminal 3 (this talker, project venv):

    export ROS_DOMAIN_ID=42 ROS_IP=127.0.0.1
    .venv/bin/python examples/talk_to_ros2.py

The listener prints one JSON line per message, e.g. ``{"event": "recv", "seq": 0, "data": "hello ROS 2 3", ...}``.
See docs/ros2.md for the walkthrough, the type mapping rules and the known limits.
"""

from __future__ import annotations

import argparse
import time

from std_msgs.msg import String

import micros_rt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--topic", default="/chatter")
    ap.add_argument("--count", type=int, default=20, help="messages to send, then exit")
    ap.add_argument("--rate", type=float, default=2.0, help="messages per second")
    args = ap.parse_args()

    micros_rt.init_node("talk_to_ros2")
    pub = micros_rt.NodeHandle().advertise(args.topic, String, 10)
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    next_t = time.monotonic()
    sent = 0
    while sent < args.count and micros_rt.ok():
        pub.publish(String(data=f"hello ROS 2 {sent}"))
        sent += 1
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    print(f"talk_to_ros2: published {sent} messages on {args.topic}", flush=True)
    micros_rt.shutdown()


if __name__ == "__main__":
    main()
