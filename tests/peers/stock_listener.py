#!/usr/bin/python3
"""Stock rospy listener for tests. Run with /usr/bin/python3; never imports micros_rt.

Prints JSON lines: {"event":"ready","node","uri","topic"} once registered with the master,
{"event":"connections","n"} when its publisher-connection count changes,
{"event":"recv","seq":k,"data":...,"msg":{...},"t":time.time(),"connection_header":{...}[,"stamp"]} per message
(connection_header has callerid, topic, type, md5sum, latching and "transport" when known),
{"event":"done","received":k} at the end. Exits after --count messages (0 = no limit) or --duration seconds.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from typing import Any, Dict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import rosgraph  # noqa: E402
import rospy  # noqa: E402

from stock_talker import emit, msg_class, summary, wait_registered  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--topic", default="/chatter")
    ap.add_argument("--type", default="std_msgs/String")
    ap.add_argument("--definition", default="", help="build --type from this message definition (no package)")
    ap.add_argument("--node-name", default=f"stock_listener_{os.getpid()}")
    ap.add_argument("--count", type=int, default=0, help="exit after this many messages (0 = no limit)")
    ap.add_argument("--duration", type=float, default=30.0, help="exit after this many seconds")
    ap.add_argument("--queue-size", type=int, default=100)
    ap.add_argument("--tcp-nodelay", action="store_true")
    ap.add_argument("--numpy", action="store_true", help="subscribe with rospy.numpy_msg(TYPE)")
    ap.add_argument("--rosout", action="store_true", help="keep the /rosout publisher (off by default)")
    args = ap.parse_args()

    t_end = time.monotonic() + args.duration
    cls = msg_class(args.type, args.definition)
    if args.numpy:
        from rospy.numpy_msg import numpy_msg

        cls = numpy_msg(cls)
    rospy.init_node(args.node_name, anonymous=False, disable_rosout=not args.rosout)
    caller_id = rospy.get_caller_id()
    topic = rospy.resolve_name(args.topic)

    lock = threading.Lock()
    received = 0
    emitted = 0  # recv lines written
    finished = threading.Event()
    sub: Any = None

    def transport_of(header: Any) -> Any:
        try:
            for c in list(sub.impl.connections):
                if getattr(c, "header", None) is header:
                    return getattr(c, "transport_type", None)
        except Exception:  # noqa: BLE001
            pass
        return None

    def callback(msg: Any) -> None:
        nonlocal received, emitted
        t = time.time()
        with lock:
            if finished.is_set() or (args.count and received >= args.count):
                return
            seq = received
            received += 1
        try:
            hdr: Dict[str, Any] = dict(getattr(msg, "_connection_header", None) or {})
            hdr.pop("message_definition", None)
            transport = transport_of(getattr(msg, "_connection_header", None))
            if transport is not None:
                hdr["transport"] = transport
            data, extra = summary(msg)
            emit("recv", seq=seq, data=data, t=t, connection_header=hdr, **extra)
        finally:
            with lock:  # lines written, not messages taken: "done" never comes before a "recv" line (rospy's
                emitted += 1  # callback thread per publisher may still be writing an earlier one)
                if args.count and emitted >= args.count:
                    finished.set()

    sub = rospy.Subscriber(topic, cls, callback, queue_size=args.queue_size, tcp_nodelay=args.tcp_nodelay)
    if not wait_registered(rosgraph.get_master_uri(), caller_id, topic, False, min(20.0, args.duration)):
        emit("error", what="not registered with master")
        return 2
    emit("ready", node=caller_id, uri=rospy.get_node_uri(), topic=topic, pid=os.getpid())

    last_n = -1
    while not rospy.is_shutdown() and not finished.is_set() and time.monotonic() < t_end:
        n = sub.get_num_connections()
        if n != last_n:
            last_n = n
            emit("connections", n=n)
        finished.wait(0.02)
    with lock:
        finished.set()
        total = received
    emit("done", received=total)
    rospy.signal_shutdown("done")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
