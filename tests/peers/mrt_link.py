"""A robot's control topic and camera sharing one link (the constrained-link scenario), one JSON event per line.

    mrt_link.py pub --seconds 6 --control-priority HIGH --image-priority LOW    # one process, two threads
    mrt_link.py sub --seconds 20                                              # counts and control latency

pub: /control (geometry_msgs/PointStamped, --control-rate Hz, queue 100, stamp = wall clock) and /image
(sensor_msgs/Image WIDTHxHEIGHT rgb8, --image-rate Hz, queue 2) from two threads, paced like rospy.Rate
(a loop more than two periods behind starts again from now: it does not catch up in a burst). It reports
how many of each it published in the window. --stock runs on plain rospy instead of micros_rt (run it
with /usr/bin/python3, without micros_rt, for the comparison).
sub: both topics; control latency (receive time - stamp) percentiles, counts, transports; with --progress-period,
what arrived in each period as a 'progress' event (examples/relay_demo.py prints them).
"""

from __future__ import annotations

import argparse
import os
import json
import sys
import threading
import time
from typing import Any, Dict, List


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields) + "\n")
    sys.stdout.flush()


def paced(rate: float, seconds: float, body: Any, stop: threading.Event, catch_up: float = 0.0) -> int:
    """Call body(i) at ``rate`` Hz for ``seconds``; returns how many calls ran.

    As rospy.Rate: a call more than two periods late is given up. With ``catch_up`` (seconds), a stall up to that
    long is caught up instead (the calls it missed run back to back): at 1 kHz, every few milliseconds another
    thread holds the GIL (the camera thread building and serialising a 921 kB frame) or a loaded machine does
    not schedule this one, and rospy.Rate's rule lost 6-16 % of the calls to that. A publish() that blocks on
    the link stalls far longer and still loses them (2-30 % ran before lanes). The catching up sends bursts,
    which a relay in the path turns into latency: tests of the relay keep rospy.Rate's rule."""
    period = 1.0 / rate
    start = time.monotonic()
    end = start + seconds
    last = start
    n = 0
    while not stop.is_set():
        now = time.monotonic()
        if now >= end:
            break
        body(n)
        n += 1
        last += period
        now = time.monotonic()
        if now - last > max(2 * period, catch_up):
            last = now
        elif last > now:
            time.sleep(last - now)
    return n


def percentile(values: List[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["pub", "sub"])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--catch-up", type=float, default=0.0,
                    help="pub: catch up stalls of the control loop up to this long (seconds; 0: rospy.Rate's rule)")
    ap.add_argument("--control-rate", type=float, default=1000.0)
    ap.add_argument("--image-rate", type=float, default=30.0)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--control-priority", default="HIGH")
    ap.add_argument("--image-priority", default="LOW")
    ap.add_argument("--image-best-effort", action="store_true")
    ap.add_argument("--image-lifespan", type=float, default=float("inf"),
                    help="pub: the camera's msg_valid_period (s): frames older than this are not sent")
    ap.add_argument("--image-topic", default="/image", help="the camera's topic name")
    ap.add_argument("--control-topic", default="/control", help="the control topic's name")
    ap.add_argument("--progress-period", type=float, default=0.0,
                    help="sub: every this many seconds after the first message, a 'progress' event: messages "
                         "and control latency p50/p99 of that period")
    ap.add_argument("--stock", action="store_true", help="plain rospy (no micros_rt)")
    ap.add_argument("--image-work-ms", type=float, default=0.0,
                    help="sub: each image callback computes in Python this long (holds the GIL: a CPU-bound node)")
    ap.add_argument("--wait-subscribers", type=float, default=60.0)
    ap.add_argument("--start-delay", type=float, default=0.0,
                    help="pub: wait this long after the first subscribers before publishing (a relay's far side "
                         "connects later than the relay)")
    ap.add_argument("--start-file", default="",
                    help="pub: wait (up to --wait-subscribers s) for this file to exist before publishing: the test "
                         "creates it when the far side's subscriber is connected")
    args = ap.parse_args()

    import rospy
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import Image

    if args.stock:
        rospy.init_node(f"link_{args.mode}", disable_signals=True)
    else:
        import micros_rt

        micros_rt.init_node(f"link_{args.mode}", disable_signals=True)
        nh = micros_rt.NodeHandle()

    if args.mode == "pub":
        if args.stock:
            control_pub = rospy.Publisher(args.control_topic, PointStamped, queue_size=100)
            image_pub = rospy.Publisher(args.image_topic, Image, queue_size=2)
        else:
            control_pub = nh.advertise_with_qos(
                args.control_topic, PointStamped, 100,
                micros_rt.AdvertiseQoSOptions(transport_priority=micros_rt.TransportPriority[args.control_priority]))
            image_pub = nh.advertise_with_qos(
                args.image_topic, Image, 2,
                micros_rt.AdvertiseQoSOptions(transport_priority=micros_rt.TransportPriority[args.image_priority],
                                              using_best_effort_protocol=args.image_best_effort,
                                              msg_valid_period=args.image_lifespan))
        deadline = time.monotonic() + args.wait_subscribers
        while (control_pub.get_num_connections() < 1 or image_pub.get_num_connections() < 1) \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        emit("ready", control=control_pub.get_num_connections(), image=image_pub.get_num_connections())
        while args.start_file and not os.path.exists(args.start_file) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(args.start_delay)
        frame = bytes(args.width * args.height * 3)
        stop = threading.Event()
        counts: Dict[str, int] = {}

        def control(i: int) -> None:
            msg = PointStamped()
            msg.header.stamp = rospy.Time.from_sec(time.time())
            msg.header.frame_id = "base"
            msg.point.x = float(i)
            control_pub.publish(msg)

        def image(i: int) -> None:
            msg = Image(height=args.height, width=args.width, encoding="rgb8", step=args.width * 3, data=frame)
            msg.header.stamp = rospy.Time.from_sec(time.time())
            msg.header.seq = i
            image_pub.publish(msg)

        threads = [threading.Thread(target=lambda: counts.__setitem__("image", paced(
            args.image_rate, args.seconds, image, stop)), daemon=True)]
        threads[0].start()
        t0 = time.monotonic()
        counts["control"] = paced(args.control_rate, args.seconds, control, stop, args.catch_up)
        elapsed = time.monotonic() - t0
        threads[0].join(args.seconds + 30)
        stats: Dict[str, Any] = {}
        links: List[Any] = []
        if not args.stock:
            import dataclasses

            from micros_rt.core.introspection import node_info   # what `micros-rt topic info` reads

            links = node_info()["links"]   # the profile's links, each paced connection's rate and use

            stats = {"control": dataclasses.asdict(control_pub.statistics()),
                     "image": dataclasses.asdict(image_pub.statistics())}
            for name, p in (("control", control_pub), ("image", image_pub)):  # how often the link had no room
                stats[name]["delayed"] = sum(q.delayed for q in p._pub.send_queues())
        emit("published", control=counts["control"], image=counts.get("image", 0), seconds=elapsed,
             intended_control=int(args.control_rate * args.seconds), statistics=stats, links=links)
        time.sleep(5.0)  # let what is in flight arrive (the subscriber reports on its own)
        emit("done")
        return 0

    got: Dict[str, Any] = {"control": 0, "image": 0, "latency": [], "image_latency": [], "transports": set(),
                           "image_transports": set()}
    lock = threading.Lock()

    def on_control(msg: Any) -> None:
        now = time.time()
        with lock:
            got["control"] += 1
            got["latency"].append(now - msg.header.stamp.to_sec())
            got["transports"].add((getattr(msg, "_connection_header", None) or {}).get("transport", "TCPROS"))

    def on_image(msg: Any) -> None:
        now = time.time()
        if args.image_work_ms:
            until, x = time.perf_counter() + args.image_work_ms / 1e3, 0
            while time.perf_counter() < until:
                x += 1
        with lock:
            got["image"] += 1
            got["image_transports"].add((getattr(msg, "_connection_header", None) or {}).get("transport", "TCPROS"))
            got["image_latency"].append(now - msg.header.stamp.to_sec())

    if args.stock:
        subs = [rospy.Subscriber(args.control_topic, PointStamped, on_control, queue_size=1000, tcp_nodelay=True),
                rospy.Subscriber(args.image_topic, Image, on_image, queue_size=2, tcp_nodelay=True)]
    else:
        subs = [nh.subscribe(args.control_topic, PointStamped, on_control, 1000),
                nh.subscribe(args.image_topic, Image, on_image, 2)]
    emit("ready")
    end = time.monotonic() + args.seconds
    last_change, last_count = time.monotonic(), -1
    connected = False
    progress_at, seen = 0.0, {"control": 0, "image": 0, "latency": 0}  # the last progress event's counts
    while time.monotonic() < end:
        time.sleep(0.1)
        with lock:
            if args.progress_period and not progress_at and got["control"] + got["image"]:
                progress_at = time.monotonic() + args.progress_period  # periods start at the first message
            if progress_at and time.monotonic() >= progress_at:
                progress_at += args.progress_period
                period = [x * 1e3 for x in got["latency"][seen["latency"]:]]
                emit("progress", control=got["control"] - seen["control"], image=got["image"] - seen["image"],
                     period=args.progress_period, p50_ms=percentile(period, 0.5), p99_ms=percentile(period, 0.99))
                seen = {"control": got["control"], "image": got["image"], "latency": len(got["latency"])}
        if not connected and all(sub.get_num_connections() > 0 for sub in subs):
            connected = True
            emit("connected")  # a publisher of each topic is linked
        with lock:
            count = got["control"] + got["image"]
        if count != last_count:
            last_change, last_count = time.monotonic(), count
        elif count > 0 and time.monotonic() - last_change > 4.0:
            break  # the stream ended
    with lock:
        lat = [x * 1e3 for x in got["latency"]]
        ordered = sorted(lat)
        cdf = [ordered[min(len(ordered) - 1, int(i * len(ordered) / 200))] for i in range(200)] if ordered else []
        # each delivery thread's nice value and the switch interval (micros_rt's receiver priority)
        nice = {t.name.rsplit(" ", 1)[-1]: os.getpriority(os.PRIO_PROCESS, t.native_id or 0)
                for t in threading.enumerate() if t.name.startswith("micros_rt delivery ")}
        emit("summary", control=got["control"], image=got["image"], transports=sorted(got["transports"]),
             nice=nice, switch_interval=sys.getswitchinterval(), image_transports=sorted(got["image_transports"]),
             p50_ms=percentile(lat, 0.5), p99_ms=percentile(lat, 0.99), max_ms=max(lat) if lat else None,
             image_p50_ms=percentile([x * 1e3 for x in got["image_latency"]], 0.5), control_cdf_ms=cdf)
    return 0


if __name__ == "__main__":
    sys.exit(main())
