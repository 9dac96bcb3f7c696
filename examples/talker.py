#!/usr/bin/env python3
"""Three topics at high, normal and low transport priority (micROS RT manual, 3.3.1).

Run against a master:  .venv/bin/python examples/talker.py [--duration 10]
"""

from __future__ import annotations

import argparse
import time

from std_msgs.msg import String

import micros_rt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rate", type=float, default=20.0, help="messages per second on each topic")
    ap.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C)")
    args = ap.parse_args()

    micros_rt.init_node("talker")
    n = micros_rt.NodeHandle()
    # advertise_with_qos() instead of advertise(): the last argument is the transport priority
    high_pub = n.advertise_with_qos("high", String, 1000, micros_rt.TransportPriority.HIGH)
    normal_pub = n.advertise_with_qos("normal", String, 1000, micros_rt.TransportPriority.NORMAL)
    low_pub = n.advertise_with_qos("low", String, 1000, micros_rt.TransportPriority.LOW)

    period = 1.0 / args.rate
    end = time.monotonic() + args.duration if args.duration > 0 else float("inf")
    count = 0
    while micros_rt.ok() and time.monotonic() < end:
        for pub, level in ((high_pub, "high"), (normal_pub, "normal"), (low_pub, "low")):
            pub.publish(String(data=f"hello world {count} ({level} priority)"))
        count += 1
        time.sleep(period)
    print(f"talker: published {count} messages on each of /high, /normal, /low", flush=True)
    micros_rt.shutdown()


if __name__ == "__main__":
    main()
