#!/usr/bin/python3
"""A plain rospy talker: rospy only, no micros_rt import, no test helpers.

Runs as a stock node (``/usr/bin/python3 plain_talker.py``) and unchanged under ``micros-rt run``
(and from a launch file). Publishes ``std_msgs/String`` "<~greeting> <n>" on ``chatter`` (a relative
name: remappings and namespaces apply). Prints JSON lines: ``ready`` (node, topic, pid, uri, greeting),
``done`` (sent). Options: --count N (0: until shutdown), --rate HZ (0: as fast as publish() returns),
--wait-subscribers N, --queue-size N, --latch, --linger S (stay S seconds after the last message, a latched
publisher serving late subscribers).
"""

import argparse
import json
import os
import sys
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
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--wait-subscribers", type=int, default=0)
    ap.add_argument("--queue-size", type=int, default=100)
    ap.add_argument("--latch", action="store_true")
    ap.add_argument("--linger", type=float, default=0.0)
    args = ap.parse_args(rospy.myargv()[1:])

    rospy.init_node("plain_talker")
    greeting = rospy.get_param("~greeting", "hello")
    pub = rospy.Publisher(args.topic, String, queue_size=args.queue_size, latch=args.latch)
    emit("ready", node=rospy.get_name(), topic=pub.resolved_name, pid=os.getpid(), uri=rospy.get_node_uri(),
         greeting=greeting, is_rospy_publisher=isinstance(pub, rospy.Publisher))
    while pub.get_num_connections() < args.wait_subscribers and not rospy.is_shutdown():
        time.sleep(0.02)
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    sent = 0
    next_t = time.monotonic()
    while not rospy.is_shutdown() and (args.count == 0 or sent < args.count):
        pub.publish(String(data="%s %d" % (greeting, sent)))
        sent += 1
        # rospy.Rate's sleep is time.sleep, which a Ctrl-C does not end (rospy's handler only sets the shutdown
        # flag): at --rate 0.1 a stop would wait 10 s. Short sleeps until the next period instead.
        next_t += period
        while period and not rospy.is_shutdown() and (left := next_t - time.monotonic()) > 0:
            time.sleep(min(0.05, left))
    emit("done", sent=sent, connections=pub.get_num_connections())
    end = time.monotonic() + args.linger
    while not rospy.is_shutdown() and time.monotonic() < end:
        time.sleep(0.05)


if __name__ == "__main__":
    main()
