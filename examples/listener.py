#!/usr/bin/env python3
"""Subscribe with a one-second time-based filter (micROS RT manual, 3.3.2).

The talker sends 20 messages per second on each topic; with the filter, about
one per second reaches the callback.

Run against a master:  .venv/bin/python examples/listener.py [--duration 10]
"""

from __future__ import annotations

import argparse
import threading
import time
from typing import Any

from std_msgs.msg import String

import micros_rt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C)")
    ap.add_argument("--topics", default="high,normal,low", help="comma-separated topics to subscribe")
    args = ap.parse_args()

    micros_rt.init_node("listener")
    n = micros_rt.NodeHandle()
    # only allow one message per second on each topic
    qos_ops = micros_rt.SubscribeQoSOptions(time_filter_duration=1.0)

    print_lock = threading.Lock()  # each topic has its own delivery thread

    def chatter_callback(msg: String, topic: Any) -> None:
        with print_lock:
            print(f"I heard on {topic}: [{msg.data}] via {msg._connection_header.get('transport', 'TCPROS')}",
                  flush=True)

    subs = [n.subscribe_with_qos(t, String, chatter_callback, 1000, qos_ops, callback_args="/" + t)
            for t in args.topics.split(",")]
    if args.duration > 0:
        end = time.monotonic() + args.duration
        while micros_rt.ok() and time.monotonic() < end:
            time.sleep(0.1)
    else:
        micros_rt.spin()
    for s in subs:
        s.unregister()
    micros_rt.shutdown()


if __name__ == "__main__":
    main()
