#!/usr/bin/python3
"""Stock rospy (run with /usr/bin/python3) talking or hearing a message type no package installs:
``robot_extra_msgs/Reading``, built at run time with genpy.dynamic. JSON lines: {"event": "ready"},
{"event": "sent", "i"}, {"event": "recv", "type", "md5", "name", "values", "level", "frame_id"}.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import genpy.dynamic
import rospy
from std_msgs.msg import Header

TYPE = "robot_extra_msgs/Reading"
DEFINITION = ("Header header\nstring name\nfloat64[] values\nint32 level\n" + "=" * 80 + "\nMSG: std_msgs/Header\n"
              + Header._full_text)


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["talk", "listen"])
    ap.add_argument("--topic", default="/extra/reading")
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args()
    rospy.init_node(f"dynamic_{args.mode}", disable_rosout=True)
    end = time.monotonic() + args.duration
    if args.mode == "talk":
        cls = genpy.dynamic.generate_dynamic(TYPE, DEFINITION)[TYPE]
        pub = rospy.Publisher(args.topic, cls, queue_size=100)
        emit("ready", md5=cls._md5sum)
        while pub.get_num_connections() < 1 and time.monotonic() < end:
            time.sleep(0.02)
        for i in range(args.count):
            msg = cls(name=f"reading {i}", values=[float(i), i + 0.5], level=i)
            msg.header.frame_id = "battery"
            pub.publish(msg)
            emit("sent", i=i)
            time.sleep(0.1)
        time.sleep(1.0)
        return 0

    def on_raw(raw: Any) -> None:
        header = raw._connection_header
        cls = genpy.dynamic.generate_dynamic(header["type"], header["message_definition"])[header["type"]]
        msg = cls().deserialize(raw._buff)
        emit("recv", type=header["type"], md5=header["md5sum"], name=msg.name, values=list(msg.values),
             level=msg.level, frame_id=msg.header.frame_id)

    rospy.Subscriber(args.topic, rospy.AnyMsg, on_raw, queue_size=100)
    emit("ready")
    while time.monotonic() < end and not rospy.is_shutdown():
        time.sleep(0.1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
