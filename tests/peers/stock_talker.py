#!/usr/bin/python3
"""Stock rospy talker for tests. Run with /usr/bin/python3; never imports micros_rt.

Prints JSON lines: {"event":"ready", "node", "uri", "topic"} once registered with the master,
{"event":"connections","n"} when its subscriber count changes,
{"event":"sent","seq":i,"data":...,"msg":{...}[,"stamp"]} per message, {"event":"done","sent":n} at the end.
Exits after --count messages (0 = until --duration), never later than --duration seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any, Dict, List, Tuple

import genpy
import rosgraph
import roslib.message
import rospy

# The helpers below (emit, msg_class, to_jsonable, summary, fill, wait_registered) are shared with
# stock_listener.py, which imports them from this module.


def emit(event: str, **fields: Any) -> None:
    """One JSON object per stdout line."""
    fields = {"event": event, **fields}
    sys.stdout.write(json.dumps(fields, default=str) + "\n")
    sys.stdout.flush()


def msg_class(type_name: str, definition: str = "") -> Any:
    """The installed class of ``type_name``; with ``definition`` (a file of ``gendeps --cat`` text), the class
    genpy builds from it at run time, as for a message package this host does not have."""
    if definition:
        import genpy.dynamic

        with open(definition) as f:
            return genpy.dynamic.generate_dynamic(type_name, f.read())[type_name]
    cls = roslib.message.get_message_class(type_name)
    if cls is None:
        raise SystemExit(f"unknown message type {type_name!r}")
    return cls


def to_jsonable(value: Any) -> Any:
    """ROS 1 message -> JSON-friendly value (time/duration -> {"secs", "nsecs"})."""
    if isinstance(value, (genpy.Time, genpy.Duration)):
        return {"secs": int(value.secs), "nsecs": int(value.nsecs)}
    if isinstance(value, genpy.Message):
        return {slot: to_jsonable(getattr(value, slot)) for slot in value.__slots__}
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if hasattr(value, "dtype") and hasattr(value, "tolist"):  # numpy array (numpy_msg): its dtype shows what arrived
        return {"ndarray": value.dtype.str, "values": value.tolist()}
    return value


def summary(msg: Any) -> Tuple[Any, Dict[str, Any]]:
    """(data, extra): data is the primitive for single-``data``-field messages (std_msgs/String, Int32, ...)
    and the whole dict otherwise; extra holds "msg" (full dict) and "stamp" {"secs","nsecs"} when stamped."""
    full = to_jsonable(msg)
    data = full["data"] if list(full) == ["data"] else full
    extra: Dict[str, Any] = {"msg": full}
    header = getattr(msg, "header", None)
    stamp = header.stamp if header is not None else getattr(msg, "stamp", None)
    if isinstance(stamp, genpy.Time):
        extra["stamp"] = {"secs": int(stamp.secs), "nsecs": int(stamp.nsecs)}
    return data, extra


def fill(msg: Any, i: int, prefix: str, now: Any) -> None:
    """Put sequence number ``i`` into a message in a type-appropriate way."""
    slots: List[str] = list(msg.__slots__)
    types = dict(zip(slots, msg._slot_types))
    if "data" in types:
        t = types["data"]
        if t == "string":
            msg.data = f"{prefix} {i}"
        elif t in ("bool",):
            msg.data = bool(i % 2)
        elif t in ("float32", "float64"):
            msg.data = float(i)
        elif t in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "byte", "char"):
            msg.data = i
    if types.get("header") == "std_msgs/Header":
        msg.header.seq = i
        msg.header.stamp = now
        msg.header.frame_id = prefix
    if msg._type == "std_msgs/Header":
        msg.seq = i
        msg.stamp = now
        msg.frame_id = prefix
    if "sample" in types and hasattr(msg.sample, "value"):  # the run-time type of the relay's test
        msg.sample.value = float(i)
    if "pose" in types and hasattr(msg.pose, "position"):
        msg.pose.position.x = float(i)
        msg.pose.orientation.w = 1.0


def wait_registered(master_uri: str, caller_id: str, topic: str, as_publisher: bool, timeout: float) -> bool:
    """Poll the master until ``caller_id`` is listed as publisher/subscriber of ``topic``."""
    master = rosgraph.Master(caller_id, master_uri=master_uri)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            pubs, subs, _ = master.getSystemState()
            for t, nodes in pubs if as_publisher else subs:
                if t == topic and caller_id in nodes:
                    return True
        except Exception:  # noqa: BLE001 - master may be restarting
            pass
        time.sleep(0.02)
    return False


# --------------------------------------------------------------------------- talker


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--topic", default="/chatter")
    ap.add_argument("--type", default="std_msgs/String")
    ap.add_argument("--definition", default="", help="build --type from this message definition (no package)")
    ap.add_argument("--rate", type=float, default=10.0, help="Hz (0 = as fast as possible)")
    ap.add_argument("--count", type=int, default=10, help="messages to send, 0 = until --duration")
    ap.add_argument("--duration", type=float, default=60.0, help="hard upper bound on run time, seconds")
    ap.add_argument("--latch", action="store_true")
    ap.add_argument("--queue-size", type=int, default=100)
    ap.add_argument("--node-name", default=f"stock_talker_{os.getpid()}")
    ap.add_argument("--prefix", default="hello")
    ap.add_argument("--wait-subscribers", type=int, default=0,
                    help="do not send before this many subscribers are connected")
    ap.add_argument("--wait-timeout", type=float, default=20.0)
    ap.add_argument("--linger", type=float, default=0.0,
                    help="stay up (serving latched/queued data) this long after the last message")
    ap.add_argument("--rosout", action="store_true", help="keep the /rosout publisher (off by default)")
    args = ap.parse_args()

    t_end = time.monotonic() + args.duration
    cls = msg_class(args.type, args.definition)
    rospy.init_node(args.node_name, anonymous=False, disable_rosout=not args.rosout)
    caller_id = rospy.get_caller_id()
    topic = rospy.resolve_name(args.topic)
    pub = rospy.Publisher(topic, cls, queue_size=args.queue_size, latch=args.latch)
    if not wait_registered(rosgraph.get_master_uri(), caller_id, topic, True, min(args.wait_timeout, args.duration)):
        emit("error", what="not registered with master")
        return 2
    emit("ready", node=caller_id, uri=rospy.get_node_uri(), topic=topic, pid=os.getpid())

    last_n = -1

    def poll_connections() -> int:
        nonlocal last_n
        n = pub.get_num_connections()
        if n != last_n:
            last_n = n
            emit("connections", n=n)
        return int(n)

    if args.wait_subscribers > 0:
        deadline = min(time.monotonic() + args.wait_timeout, t_end)
        while poll_connections() < args.wait_subscribers:
            if rospy.is_shutdown():
                return 0
            if time.monotonic() > deadline:
                emit("error", what=f"timed out waiting for {args.wait_subscribers} subscribers")
                return 3
            time.sleep(0.01)

    period = 1.0 / args.rate if args.rate > 0 else 0.0
    next_t = time.monotonic()
    sent = 0
    while not rospy.is_shutdown() and time.monotonic() < t_end and (args.count == 0 or sent < args.count):
        msg = cls()
        fill(msg, sent, args.prefix, rospy.Time.now())
        pub.publish(msg)
        data, extra = summary(msg)
        emit("sent", seq=sent, data=data, t=time.time(), **extra)
        sent += 1
        poll_connections()
        if period:
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    linger_end = min(time.monotonic() + args.linger, t_end)
    while not rospy.is_shutdown() and time.monotonic() < linger_end:
        poll_connections()
        time.sleep(0.02)
    emit("done", sent=sent)
    rospy.signal_shutdown("done")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
