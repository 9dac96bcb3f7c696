"""A micros_rt node for integration tests: talks or listens, one JSON event per stdout line.

Run with the project's venv (.venv/bin/python). Examples:

    mrt_peer.py talk --topic chatter --count 50 --rate 20 --qos '{"transport_priority": "HIGH"}'
    mrt_peer.py listen --topic chatter --duration 5 --hints dds,tcp
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from typing import Any, Dict

import genpy
import roslib.message

import micros_rt


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields, default=str) + "\n")
    sys.stdout.flush()


def msg_to_dict(msg: Any) -> Any:
    if isinstance(msg, genpy.Message):
        return {k: msg_to_dict(getattr(msg, k)) for k in msg.__slots__}
    if isinstance(msg, (genpy.Time, genpy.Duration)):
        return {"secs": msg.secs, "nsecs": msg.nsecs}
    if isinstance(msg, bytes):
        return {"bytes_len": len(msg), "head": list(msg[:8])}
    if isinstance(msg, (list, tuple)):
        return [msg_to_dict(x) for x in msg]
    return msg


def fill(msg: Any, text: str, i: int, stamp: bool) -> Any:
    if hasattr(msg, "data") and isinstance(getattr(msg, "data"), str):
        msg.data = text
    elif hasattr(msg, "data") and isinstance(getattr(msg, "data"), int):
        msg.data = i
    if stamp and getattr(msg, "_has_header", False):
        msg.header.stamp = genpy.Time.from_sec(time.time())
        msg.header.frame_id = text
    return msg


class _JsonLogHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        emit("log", level=record.levelname, text=record.getMessage())


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["talk", "listen"])
    ap.add_argument("--topic", default="chatter")
    ap.add_argument("--type", default="std_msgs/String")
    ap.add_argument("--node-name", default=None)
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--count", type=int, default=50)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--queue-size", type=int, default=100)
    ap.add_argument("--latch", action="store_true")
    ap.add_argument("--qos", default=None, help="JSON dict of Advertise/SubscribeQoSOptions fields")
    ap.add_argument("--hints", default=None, help="comma list: dds,tcp")
    ap.add_argument("--prefix", default="hello")
    ap.add_argument("--stamp", action="store_true", help="stamp Header with the wall clock")
    ap.add_argument("--wait-subscribers", type=int, default=0)
    ap.add_argument("--linger", type=float, default=0.5, help="seconds to stay up after the last message")
    ap.add_argument("--deadline-events", action="store_true")
    args = ap.parse_args()

    log = logging.getLogger("micros_rt")
    log.setLevel(logging.INFO)
    log.addHandler(_JsonLogHandler())
    log.propagate = False

    data_class = roslib.message.get_message_class(args.type)
    if data_class is None:
        emit("error", text=f"unknown type {args.type}")
        return 2
    name = args.node_name or f"mrt_{args.mode}"
    micros_rt.init_node(name, disable_signals=False)
    nh = micros_rt.NodeHandle()
    qos: Dict[str, Any] = json.loads(args.qos) if args.qos else {}

    if args.mode == "talk":
        if qos:
            pub = nh.advertise_with_qos(args.topic, data_class, args.queue_size,
                                        micros_rt.AdvertiseQoSOptions.from_dict(qos), latch=args.latch)
        else:
            pub = nh.advertise(args.topic, data_class, args.queue_size, latch=args.latch)
        emit("ready", topic=pub.resolved_name)
        deadline = time.monotonic() + 30.0
        while pub.get_num_connections() < args.wait_subscribers and time.monotonic() < deadline:
            time.sleep(0.02)
        period = 1.0 / args.rate if args.rate > 0 else 0.0
        start = time.monotonic()
        for i in range(args.count):
            if micros_rt.is_shutdown():
                break
            text = f"{args.prefix} {i}"
            pub.publish(fill(data_class(), text, i, args.stamp))
            emit("sent", seq=i, data=text, connections=pub.get_num_connections())
            next_t = start + (i + 1) * period
            while time.monotonic() < next_t:
                time.sleep(min(0.005, next_t - time.monotonic()) if next_t > time.monotonic() else 0)
        end = time.monotonic() + args.linger
        while time.monotonic() < end and not micros_rt.is_shutdown():
            time.sleep(0.02)
        emit("done", connections=pub.get_num_connections())
    else:
        hints = None
        if args.hints:
            hints = micros_rt.TransportHints()
            for h in args.hints.split(","):
                hints = hints.dds() if h.strip() == "dds" else hints.tcp()

        def on_deadline(info: Any) -> None:
            emit("deadline", silent_for=info.silent_for, total=info.total_count)

        def cb(msg: Any) -> None:
            header = getattr(msg, "_connection_header", {}) or {}
            emit("recv", data=getattr(msg, "data", None), t=time.time(),
                 transport=header.get("transport", "TCPROS"), callerid=header.get("callerid"),
                 msg=msg_to_dict(msg) if not hasattr(msg, "data") or not isinstance(msg.data, (str, int)) else None)

        if qos or args.deadline_events:
            if args.deadline_events:
                qos = dict(qos)
            opts = micros_rt.SubscribeQoSOptions.from_dict(qos)
            if args.deadline_events:
                import dataclasses
                opts = dataclasses.replace(opts, deadline_cb=on_deadline)
            sub = nh.subscribe_with_qos(args.topic, data_class, cb, args.queue_size, opts)
        else:
            sub = nh.subscribe(args.topic, data_class, cb, args.queue_size, hints)
        emit("ready", topic=sub.resolved_name)
        end = time.monotonic() + args.duration
        got_all = False
        while time.monotonic() < end and not micros_rt.is_shutdown():
            if args.count and not got_all:
                pass
            time.sleep(0.05)
            emit_status = getattr(main, "_last_status", 0.0)
            if time.monotonic() - emit_status > 0.5:
                main._last_status = time.monotonic()  # type: ignore[attr-defined]
                emit("status", transports=sub.connection_transports())
        emit("done", transports=sub.connection_transports(), latency_count=sub.latency.count)
    micros_rt.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
