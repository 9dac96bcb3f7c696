"""A micros_rt sequence-number stream for loss tests: one JSON summary line per stdout line.

    mrt_seq.py send --topic /s --count 100000 --size 64 [--queue-size N]
    mrt_seq.py recv --topic /s --count 100000 --timeout 60 [--queue-size N] [--hints tcp] [--slow 0.01]

Payloads are std_msgs/UInt8MultiArray whose first 8 bytes are the sequence number (little endian).
``recv`` prints {"event": "ready"} once subscribed, then {"event": "summary", ...} with received, distinct,
duplicates, out_of_order, missing and the subscriber's statistics().
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import sys
import time
from typing import Any, List, Optional

import micros_rt
from std_msgs.msg import UInt8MultiArray


#: the sequence number of a warm-up message (never counted)
WARMUP = 2 ** 64 - 1


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields, default=str) + "\n")
    sys.stdout.flush()


def queue_size(text: str) -> Optional[int]:
    return None if text == "none" else int(text)


def send(a: argparse.Namespace, nh: micros_rt.NodeHandle) -> int:
    if a.best_effort or a.latency_budget:
        pub = nh.advertise_with_qos(a.topic, UInt8MultiArray, a.queue_size,
                                    micros_rt.AdvertiseQoSOptions(using_best_effort_protocol=a.best_effort,
                                                                  latency_budget=a.latency_budget))
    else:
        pub = nh.advertise(a.topic, UInt8MultiArray, a.queue_size)
    deadline = time.monotonic() + 30.0
    while pub.get_num_connections() < a.subscribers and time.monotonic() < deadline:
        time.sleep(0.01)
    emit("ready", connections=pub.get_num_connections())
    warm = UInt8MultiArray(data=struct.pack("<Q", WARMUP) + bytes(max(a.size - 8, 0)))
    while a.start_file and not os.path.exists(a.start_file) and time.monotonic() < deadline + a.timeout:
        if a.warmup:
            pub.publish(warm)  # until the subscriber has heard one (the test then says start)
        time.sleep(0.05)  # the test says when the subscriber has matched this writer too
    time.sleep(0.3)
    pad = bytes(max(a.size - 8, 0))
    msg = UInt8MultiArray()
    start = time.monotonic()
    period = 1.0 / a.rate if a.rate > 0 else 0.0
    for i in range(a.count):
        msg.data = struct.pack("<Q", i) + pad
        pub.publish(msg)
        if period and (i + 1) % a.burst == 0:
            delay = start + (i + 1) // a.burst * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if a.progress and i % a.progress == 0:
                emit("progress", i=i)
    elapsed = time.monotonic() - start
    stats = pub.statistics()
    emit("sent", count=a.count, seconds=elapsed, blocked_seconds=stats.blocked_seconds, published=stats.published)
    end = time.monotonic() + a.linger
    while time.monotonic() < end and not micros_rt.is_shutdown():  # a stop (SIGINT/SIGTERM) ends the linger
        time.sleep(0.05)
    return 0


def recv(a: argparse.Namespace, nh: micros_rt.NodeHandle) -> int:
    seen: List[int] = []
    arrivals: List[float] = []
    warmed: List[bool] = []

    def cb(msg: Any) -> None:
        seq = struct.unpack_from("<Q", msg.data)[0]
        if seq == WARMUP:
            if not warmed:
                warmed.append(True)
                emit("warmed")
            return
        seen.append(seq)
        arrivals.append(time.monotonic())
        if a.slow:
            time.sleep(a.slow)

    hints = micros_rt.TransportHints()
    for p in a.hints.split(","):
        hints = hints.tcp() if p == "tcp" else hints.dds() if p == "dds" else hints
    if a.best_effort or a.deadline:
        qos = micros_rt.SubscribeQoSOptions(
            using_best_effort_protocol=a.best_effort, ordered_by_sending_timestamp=False,
            deadline=a.deadline or float("inf"),
            deadline_cb=(lambda miss: emit("deadline", silent_for=miss.silent_for)) if a.deadline else None)
        sub = nh.subscribe_with_qos(a.topic, UInt8MultiArray, cb, a.queue_size, qos)
    else:
        sub = nh.subscribe(a.topic, UInt8MultiArray, cb, a.queue_size, hints)
    emit("ready")
    deadline = time.monotonic() + a.timeout
    first: Optional[float] = None
    last_n, last_change = 0, time.monotonic()
    connected = False
    while time.monotonic() < deadline and len(seen) < a.count and not micros_rt.is_shutdown():
        time.sleep(0.05)
        if not connected and sub.get_num_connections() > 0:
            connected = True  # this side matched a publisher (over DDS: the reader found the writer)
            emit("connected", transports=sorted(set(sub.connection_transports().values())))
        if seen and first is None:
            first = time.monotonic()
        if len(seen) != last_n:
            last_n, last_change = len(seen), time.monotonic()
        elif first is not None and time.monotonic() - last_change > a.idle:
            break
    got = list(seen)
    distinct = set(got)
    gaps: List[List[int]] = []  # the missing sequence numbers as [first, last] ranges (the first 20)
    for i in sorted(set(range(a.count)) - distinct):
        if gaps and gaps[-1][1] == i - 1:
            gaps[-1][1] = i
        elif len(gaps) < 20:
            gaps.append([i, i])
    out_of_order = sum(1 for x, y in zip(got, got[1:]) if y < x)
    s = sub.statistics()
    emit("summary", received=len(got), distinct=len(distinct), duplicates=len(got) - len(distinct),
         out_of_order=out_of_order, missing=a.count - len(distinct), missing_ranges=gaps,
         transports=sorted(set(sub.connection_transports().values())),
         stats={k: getattr(s, k) for k in s.__dataclass_fields__}, latency=sub.latency.summary(),
         longest_gap=max((b - a for a, b in zip(arrivals, arrivals[1:])), default=0.0),
         seconds=(last_change - first) if first is not None else None)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["send", "recv"])
    ap.add_argument("--topic", default="/seq")
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--queue-size", type=queue_size, default=None)
    ap.add_argument("--subscribers", type=int, default=1)
    ap.add_argument("--hints", default="")
    ap.add_argument("--slow", type=float, default=0.0)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--idle", type=float, default=5.0, help="stop after this long without a new message")
    ap.add_argument("--linger", type=float, default=3.0)
    ap.add_argument("--start-file", default="", help="send: publish once this file exists (recv says 'connected')")
    ap.add_argument("--warmup", action="store_true",
                    help="send: until the start file exists, publish a warm-up message (not counted; recv says "
                         "'warmed' at the first) every 50 ms")
    ap.add_argument("--rate", type=float, default=0.0, help="send: messages (with --burst, bursts) per second (0: as fast as possible)")
    ap.add_argument("--burst", type=int, default=1, help="send: with --rate, this many messages back to back each time")
    ap.add_argument("--progress", type=int, default=0, help="send: a progress event every N messages")
    ap.add_argument("--best-effort", action="store_true")
    ap.add_argument("--latency-budget", type=float, default=0.0, help="send: batch writes within this budget (s)")
    ap.add_argument("--deadline", type=float, default=0.0, help="recv: deadline (s), misses printed as events")
    a = ap.parse_args()
    micros_rt.init_node(f"mrt_seq_{a.mode}", anonymous=True, disable_signals=False)
    nh = micros_rt.NodeHandle()
    return send(a, nh) if a.mode == "send" else recv(a, nh)


if __name__ == "__main__":
    sys.exit(main())
