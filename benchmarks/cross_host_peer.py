#!/usr/bin/env python3
"""A paced sensor stream between hosts, one endpoint per process (benchmarks/cross_host.py runs it).

    python cross_host_peer.py IMPL stream --kind image_vga --rate 30 --seconds 5 --subs 4
    python cross_host_peer.py IMPL sink --kind image_vga

IMPL as in benchmarks/peer.py (mrt_dds, mrt_tcpros, rospy). stream: waits for ``--subs`` subscribers, then
publishes ``--rate`` Hz for ``--seconds`` (paced like rospy.Rate), each message stamped with the wall clock
(hosts in network namespaces share it); publisher queue ``--queue`` (2, as a camera driver). sink: one
subscriber (queue ``--queue``; rospy with tcp_nodelay), one-way latency (receive time - stamp) per message.
The driver tells the sink how many were sent (``SENT n`` on stdin); the sink reports when it has them all or
heard nothing for ``--drain`` s. JSON lines on stdout as peer.py's.
"""

import argparse
import os
import signal
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peer  # noqa: E402  (Msgs, Ros1, emit, the stdin command reader)
from peer import CMDS, STOP, emit  # noqa: E402


def percentile(values, q):
    if not values:
        return None
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def stamp_now(m, tr):
    if tr.mrt:
        import rospy
    else:
        rospy = tr.m
    m.header.stamp = rospy.Time.from_sec(time.time())


def role_stream(a, tr, msgs):
    if tr.mrt:
        p = tr.nh.advertise(a.topic, msgs.cls, a.queue)
    else:
        p = tr.m.Publisher(a.topic, msgs.cls, queue_size=a.queue, tcp_nodelay=True)
    peer.wait_matched(tr, p, a.subs, time.monotonic() + a.timeout, settle=1.0)
    emit("ready")
    period = 1.0 / a.rate
    start = time.monotonic()
    end, last, n = start + a.seconds, start, 0
    c0 = time.process_time()
    took = []
    while not STOP.is_set():
        now = time.monotonic()
        if now >= end:
            break
        m = msgs.make(n)
        stamp_now(m, tr)
        t = time.perf_counter()
        p.publish(m)
        took.append((time.perf_counter() - t) * 1e3)
        n += 1
        last += period
        now = time.monotonic()
        if now - last > 2 * period:
            last = now
        elif last > now:
            time.sleep(last - now)
    emit("sent", sent=n, seconds=time.monotonic() - start, cpu_s=time.process_time() - c0,
         publish_p50_ms=percentile(took, 0.5))
    deadline = time.monotonic() + a.timeout
    while not STOP.is_set() and time.monotonic() < deadline and "DONE" not in CMDS:
        time.sleep(0.05)


def role_sink(a, tr, msgs):
    lock = threading.Lock()
    lat, seen = [], set()

    def cb(m):
        now = time.time()
        with lock:
            s = msgs.seq(m)
            if s not in seen:
                seen.add(s)
                lat.append((now - m.header.stamp.to_sec()) * 1e3)

    if tr.mrt:
        hints = tr.m.TransportHints().tcp() if a.impl == "mrt_tcpros" else None
        keep = tr.nh.subscribe(a.topic, msgs.cls, cb, a.queue, hints)
    else:
        keep = tr.m.Subscriber(a.topic, msgs.cls, cb, queue_size=a.queue, tcp_nodelay=True)
    emit("ready")
    deadline = time.monotonic() + a.timeout
    sent, last_n, last_change = None, 0, time.monotonic()
    while not STOP.is_set() and time.monotonic() < deadline:
        time.sleep(0.02)
        if sent is None:
            c = next((c for c in CMDS if c.startswith("SENT ")), None)
            if c:
                sent = int(c.split()[1])
                last_change = time.monotonic()
        with lock:
            n = len(seen)
        if n != last_n:
            last_n, last_change = n, time.monotonic()
        if sent is not None and (n >= sent or time.monotonic() - last_change > a.drain):
            break
    with lock:
        got = list(lat)
    emit("result", received=len(got), sent=sent, p50_ms=percentile(got, 0.5), p99_ms=percentile(got, 0.99),
         max_ms=max(got) if got else None, lat_ms=[round(x, 3) for x in got])
    del keep
    while not STOP.is_set() and time.monotonic() < deadline and "DONE" not in CMDS:
        time.sleep(0.05)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("impl", choices=("mrt_dds", "mrt_tcpros", "rospy"))
    ap.add_argument("role", choices=("stream", "sink"))
    ap.add_argument("--topic", default="/xh_stream")
    ap.add_argument("--kind", default="image_vga", choices=peer.KINDS)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--queue", type=int, default=2)
    ap.add_argument("--subs", type=int, default=1)
    ap.add_argument("--drain", type=float, default=2.0)
    ap.add_argument("--timeout", type=float, default=60.0)
    a = ap.parse_args()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.set())
    threading.Thread(target=peer._stdin_reader, daemon=True).start()
    code, tr = 0, None
    try:
        msgs = peer.Msgs(a.impl, a.kind, 0)
        tr = peer.transport(a.impl, f"xh_{a.role}", msgs)
        (role_stream if a.role == "stream" else role_sink)(a, tr, msgs)
    except SystemExit as exc:
        emit("error", error=str(exc.code))
        code = 1
    except BaseException as exc:
        emit("error", error=f"{type(exc).__name__}: {exc}")
        code = 1
    finally:
        sys.stdout.flush()
        if tr is not None:
            t = threading.Thread(target=tr.close, daemon=True)
            t.start()
            t.join(2.0)
        os._exit(code)


if __name__ == "__main__":
    main()
