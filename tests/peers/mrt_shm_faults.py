"""micros_rt nodes for the shared-memory fault tests (issue 46): one JSON event per stdout line.

    mrt_shm_faults.py flood --topic /f [--size 64] [--stop-with signal_shutdown] [--queue-size N]
                            [--grow-after N --grow-size BYTES]
        publish std_msgs/String as fast as it can (queue_size=None, lossless) until shut down; prints
        {"event": "flooding"} once 2,000 were sent to a subscriber, {"event": "stopped", ...} on the way out
        (with the longest publish() it saw)
    mrt_shm_faults.py count --topic /f [--duration 60]
        subscribe and count (no line per message); prints {"event": "ready"}, then {"event": "count", ...}
        every 0.2 s with the messages, their sequence gaps and the subscription's connections
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import threading
import time
from typing import Any, List

import micros_rt
import rospy
from std_msgs.msg import String


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields, default=str) + "\n")
    sys.stdout.flush()


def flood(a: argparse.Namespace) -> int:
    micros_rt.init_node(a.node_name or "shm_flood", anonymous=a.node_name is None)
    pub = micros_rt.NodeHandle().advertise(a.topic, String, a.queue_size or None)
    emit("advertised")
    deadline = time.monotonic() + 60
    while (a.wait and pub.get_num_connections() < 1 and time.monotonic() < deadline
           and not micros_rt.is_shutdown()):
        time.sleep(0.01)
    msg = String(data="x" * a.size)
    sent = 0
    errors = 0
    longest = 0.0  # the longest publish() (a forged channel must not hold it)
    period = 1.0 / a.rate if a.rate > 0 else 0.0
    next_at = time.monotonic()
    if a.stop_with == "signal_shutdown":
        def stop() -> None:
            emit("shutting_down")
            rospy.signal_shutdown("the test's rospy.signal_shutdown")

        threading.Timer(a.after, stop).start()
    while not micros_rt.is_shutdown():
        if period:
            next_at += period
            time.sleep(max(0.0, next_at - time.monotonic()))
        t0 = time.monotonic()
        try:
            pub.publish(msg)
            longest = max(longest, time.monotonic() - t0)
        except Exception as exc:  # publish() on a closing node: what it says is not the point here
            errors += 1
            if errors == 1:
                emit("publish_error", error=f"{type(exc).__name__}: {exc}")
            continue
        sent += 1
        if sent == a.grow_after:
            msg = String(data="y" * a.grow_size)  # a channel must grow for it
            emit("grown", sent=sent)
        if sent == a.flooding_after:
            emit("flooding", connections=pub.get_num_connections())
        if a.report and sent % a.report == 0:
            emit("progress", sent=sent, longest_publish=longest, connections=pub.get_num_connections())
    emit("stopped", sent=sent, errors=errors, longest_publish=longest, statistics=dataclasses.asdict(pub.statistics()))
    return 0


def count(a: argparse.Namespace) -> int:
    micros_rt.init_node(a.node_name or "shm_count", anonymous=a.node_name is None)
    seen: List[int] = [0]

    def on_msg(msg: Any) -> None:
        seen[0] += 1

    hints = micros_rt.TransportHints()
    for name in filter(None, a.hints.split(",")):
        hints = getattr(hints, name)()  # shm, dds, tcp
    sub = micros_rt.NodeHandle().subscribe(a.topic, String, on_msg, None, hints if a.hints else None)
    emit("ready")
    end = time.monotonic() + a.duration
    while time.monotonic() < end and not micros_rt.is_shutdown():
        emit("count", received=seen[0], connections=sub.get_num_connections(),
             transports=sorted(sub.connection_transports().values()))
        time.sleep(0.2)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["flood", "count"])
    ap.add_argument("--topic", default="/flood")
    ap.add_argument("--node-name", default=None)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--stop-with", choices=["signal", "signal_shutdown"], default="signal")
    ap.add_argument("--after", type=float, default=3.0, help="flood --stop-with signal_shutdown: seconds")
    ap.add_argument("--rate", type=float, default=0.0, help="flood: messages per second (0: as fast as it can)")
    ap.add_argument("--no-wait", dest="wait", action="store_false", help="flood: start before a subscriber")
    ap.add_argument("--flooding-after", type=int, default=2000)
    ap.add_argument("--queue-size", type=int, default=0, help="flood: 0 is None (lossless), else KEEP_LAST")
    ap.add_argument("--grow-after", type=int, default=0, help="flood: after this many, messages of --grow-size")
    ap.add_argument("--grow-size", type=int, default=4 << 20)
    ap.add_argument("--hints", default="", help="count: TransportHints, a comma list of shm, dds, tcp")
    ap.add_argument("--report", type=int, default=0, help="flood: a progress line every N messages")
    a = ap.parse_args()
    return flood(a) if a.mode == "flood" else count(a)


if __name__ == "__main__":
    sys.exit(main())
