"""A micros_rt node for integration tests: talks or listens, one JSON event per stdout line.

Run with the project's venv (.venv/bin/python). Examples:

    mrt_peer.py talk --topic chatter --count 50 --rate 20 --qos '{"transport_priority": "HIGH"}'
    mrt_peer.py listen --topic chatter --duration 5 --hints dds,tcp
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import os
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


def fill(msg: Any, text: str, i: int, stamp: bool, clock_offset: float = 0.0) -> Any:
    if hasattr(msg, "data") and isinstance(getattr(msg, "data"), str):
        msg.data = text
    elif hasattr(msg, "data") and isinstance(getattr(msg, "data"), int):
        msg.data = i
    if stamp and getattr(msg, "_has_header", False):
        msg.header.stamp = genpy.Time.from_sec(time.time() + clock_offset)
        msg.header.frame_id = text
    return msg


def side_writer(pub: Any, protocol: str) -> Any:
    """The writer of a publisher's negotiated side (``DDS``, ``SHM``), None when it has none (yet)."""
    side = pub._pub.sides.get(protocol) if pub._pub is not None else None
    return None if side is None else side.writer


def play_clock_offset(pub: Any, offset: float) -> None:
    """Play a publisher whose clock is ``offset`` seconds off (a lagging host) without touching the
    system clock: this peer's DDS and shared-memory writes carry shifted source timestamps. Test-only, so it
    lives here."""
    from micros_rt.cyclone import import_cyclonedds

    import_cyclonedds()   # the one locked first import: the node's threads may be importing it now
    from cyclonedds._clayer import ddspy_write_ts

    shift = int(offset * 1e9)
    if os.environ.get("MICROS_RT_DISABLE_SHM", "0") != "1":
        from micros_rt.transports.shm import channel as shm_channel

        send = shm_channel.ShmChannel.try_send
        shm_channel.ShmChannel.try_send = (  # type: ignore[method-assign]
            lambda self, body, source_ns=0: send(self, body, source_ns or time.time_ns() + shift))
    writer = side_writer(pub, "DDS")
    if writer is None:
        return  # no DDS writer (hints, DDS off or not yet opened)
    ref = writer._ref
    writer._write = lambda data: ddspy_write_ts(ref, data, time.time_ns() + shift)


def pattern_bytes(n: int, seed: int) -> bytes:
    """Deterministic test payload; the same function lives in ros2_peer.py and the interop tests."""
    base = bytes((seed + 7 * k) & 0xFF for k in range(256))
    return (base * (n // 256 + 1))[:n]


def full_dict(msg: Any) -> Any:
    """Every field (--full-msg): uint8[] as {bytes_len, sha256, head}, time as {secs, nsecs}."""
    if isinstance(msg, genpy.Message):
        return {k: full_dict(getattr(msg, k)) for k in msg.__slots__}
    if isinstance(msg, (genpy.Time, genpy.Duration)):
        return {"secs": msg.secs, "nsecs": msg.nsecs}
    if isinstance(msg, (bytes, bytearray)):
        return {"bytes_len": len(msg), "sha256": hashlib.sha256(msg).hexdigest(), "head": list(msg[:8])}
    if isinstance(msg, (list, tuple)):
        return [full_dict(x) for x in msg]
    if hasattr(msg, "dtype") and hasattr(msg, "tolist"):  # numpy array (--numpy): its dtype shows what arrived
        return {"ndarray": msg.dtype.str, "values": msg.tolist()}
    return msg


def as_numpy(msg: Any) -> Any:
    """--numpy talk: every numeric array field (not uint8[]/char[]/bool[]) becomes a numpy array of its dtype."""
    import numpy

    dtypes = {"float32": "<f4", "float64": "<f8", "int8": "i1", "byte": "i1", "int16": "<i2", "uint16": "<u2",
              "int32": "<i4", "uint32": "<u4", "int64": "<i8", "uint64": "<u8"}
    for key, slot in zip(msg.__slots__, msg._slot_types):
        value = getattr(msg, key)
        base = slot.split("[")[0]
        if slot.endswith("]") and base in dtypes:
            setattr(msg, key, numpy.array(value, dtype=dtypes[base]))
        elif isinstance(value, genpy.Message):
            as_numpy(value)
        elif slot.endswith("]") and value and isinstance(value[0], genpy.Message):
            for item in value:
                as_numpy(item)
    return msg


def set_fields(msg: Any, values: Dict[str, Any], i: int) -> Any:
    """Fill a genpy message from a dict (--data-json): nested dicts for messages and time
    ({"secs", "nsecs"}), lists of dicts for message arrays, {"$bytes": {"len", "seed"}} for uint8[];
    "{i}" in strings becomes the message number."""
    types = dict(zip(msg.__slots__, msg._slot_types))
    for key, val in values.items():
        if key not in types:
            raise SystemExit(f"{msg._type} has no field {key!r}")
        slot = types[key]
        base = slot.split("[")[0]
        if isinstance(val, dict) and "$bytes" in val:
            spec = val["$bytes"]
            setattr(msg, key, pattern_bytes(int(spec["len"]), int(spec.get("seed", 0))))
        elif base in ("time", "duration") and isinstance(val, dict):
            cls = genpy.Time if base == "time" else genpy.Duration
            setattr(msg, key, cls(int(val.get("secs", 0)), int(val.get("nsecs", 0))))
        elif isinstance(val, dict):
            set_fields(getattr(msg, key), val, i)
        elif isinstance(val, list) and slot.endswith("]") and val and isinstance(val[0], dict):
            cls = roslib.message.get_message_class(base if base != "Header" else "std_msgs/Header")
            setattr(msg, key, [set_fields(cls(), v, i) for v in val])
        else:
            if isinstance(val, str):
                val = val.replace("{i}", str(i))
            if base in ("uint8", "char") and slot.endswith("]") and isinstance(val, list):
                val = bytes(val)
            setattr(msg, key, val)
    return msg


class _JsonLogHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        emit("log", level=record.levelname, text=record.getMessage())


def dataclasses_asdict(value: Any) -> Dict[str, Any]:
    import dataclasses

    return dataclasses.asdict(value)


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
    ap.add_argument("--hints", default=None, help="comma list: shm,dds,tcp")
    ap.add_argument("--prefix", default="hello")
    ap.add_argument("--stamp", action="store_true", help="stamp Header with the wall clock")
    ap.add_argument("--wait-subscribers", type=int, default=0)
    ap.add_argument("--wait-timeout", type=float, default=30.0,
                    help="talk: how long --wait-subscribers and --wait-dds-readers wait together (seconds)")
    ap.add_argument("--linger", type=float, default=0.5, help="seconds to stay up after the last message")
    ap.add_argument("--start-delay", type=float, default=0.0,
                    help="talk: seconds to wait after the subscribers are there (a ROS 2 reader's own discovery)")
    ap.add_argument("--start-file", default="",
                    help="talk: send the counted messages once this file exists (the test has seen the readers match)")
    ap.add_argument("--warmup-file", default="",
                    help="talk: publish 'warmup' every 50 ms until this file exists, then the counted messages")
    ap.add_argument("--deadline-events", action="store_true")
    ap.add_argument("--callback-sleep", type=float, default=0.0,
                    help="listen: seconds every callback sleeps after printing (a slow subscriber)")
    ap.add_argument("--clock-offset", type=float, default=0.0,
                    help="talk: add this many seconds to every DDS and SHM source timestamp and --stamp Header "
                         "stamp (a host whose clock is off)")
    ap.add_argument("--log-debug", action="store_true", help="print micros_rt DEBUG log records too")
    ap.add_argument("--data-json", default=None,
                    help='talk: JSON dict of field values, e.g. \'{"data": "x {i}"}\' (see set_fields)')
    ap.add_argument("--full-msg", action="store_true",
                    help="listen: print every received message in full (recv event key 'msg')")
    ap.add_argument("--exit-after", type=int, default=0, help="listen: exit after this many messages")
    ap.add_argument("--numpy", action="store_true",
                    help="use rospy.numpy_msg(TYPE): talk fills numeric arrays with numpy arrays, listen gets them")
    ap.add_argument("--with-qos", action="store_true",
                    help="use advertise_with_qos/subscribe_with_qos even when --qos is empty")
    ap.add_argument("--slow-topic", default=None,
                    help="listen: also subscribe to this topic (queue_size 1) with a callback that sleeps "
                         "--slow-sleep seconds per message; 'slow_recv' events, its statistics at 'done'")
    ap.add_argument("--slow-sleep", type=float, default=0.5)
    ap.add_argument("--first", default=None, metavar="TOPIC=PRIORITY",
                    help="talk: advertise this std_msgs/String topic at this transport priority first (it sends "
                         "nothing; it gives the process participant its priority)")
    ap.add_argument("--wait-dds-readers", type=int, default=0,
                    help="talk: wait (see --wait-timeout) until the DDS writer matches this many readers (e.g. rclpy)")
    args = ap.parse_args()

    def capture_logs() -> None:
        # micros_rt logs under rospy's "rosout" logger; rospy's logging setup in init_node
        # resets its children, so this runs before (early errors) and again after it.
        log = logging.getLogger("rosout.micros_rt")
        log.setLevel(logging.DEBUG if args.log_debug else logging.INFO)
        log.handlers = [_JsonLogHandler()]
        log.propagate = False

    capture_logs()

    if args.type.count("/") == 2:   # a ROS 2 type name: ROS 1's package, else built from the ROS 2 installation
        data_class = micros_rt.ros2_message_class(args.type)
    else:
        data_class = roslib.message.get_message_class(args.type)
    if data_class is None:
        emit("error", text=f"unknown type {args.type}")
        return 2
    if args.numpy:
        from rospy.numpy_msg import numpy_msg

        data_class = numpy_msg(data_class)
    name = args.node_name or f"mrt_{args.mode}"
    micros_rt.init_node(name, disable_signals=False)
    capture_logs()
    nh = micros_rt.NodeHandle()
    qos: Dict[str, Any] = json.loads(args.qos) if args.qos else {}

    if args.mode == "talk":
        if args.first:
            first_topic, _, first_priority = args.first.partition("=")
            nh.advertise_with_qos(first_topic, roslib.message.get_message_class("std_msgs/String"), 10,
                                  micros_rt.TransportPriority.parse(first_priority))
        if qos or args.with_qos:
            pub = nh.advertise_with_qos(args.topic, data_class, args.queue_size,
                                        micros_rt.AdvertiseQoSOptions.from_dict(qos), latch=args.latch)
        else:
            pub = nh.advertise(args.topic, data_class, args.queue_size, latch=args.latch)
        if args.clock_offset:
            play_clock_offset(pub, args.clock_offset)
        emit("ready", topic=pub.resolved_name)
        deadline = time.monotonic() + args.wait_timeout
        while pub.get_num_connections() < args.wait_subscribers and time.monotonic() < deadline:
            time.sleep(0.02)

        def dds_readers() -> int:
            writer = side_writer(pub, "DDS")
            return int(writer.matched_count) if writer is not None else 0

        while dds_readers() < args.wait_dds_readers and time.monotonic() < deadline:
            time.sleep(0.02)
        if args.wait_dds_readers:
            from micros_rt.extend import dds_backend

            writer, backend = side_writer(pub, "DDS"), dds_backend()
            # the participant the topic's writer is on, and the process's (another one: a priority participant)
            emit("dds_matched", n=dds_readers(), participant=writer.participant.guid if writer is not None else None,
                 process_participant=backend.participant.guid if backend is not None else None)
        values = json.loads(args.data_json) if args.data_json else None
        # until the test says start (it has seen one arrive): "warmup" messages, so the counted ones go out once
        # the subscriber's DDS reader hears this writer (it joins a writer's stream at the first heartbeat it
        # hears; over a lossy link the writer's first ones can come before that and are not delivered to it)
        while args.warmup_file and not os.path.exists(args.warmup_file) and time.monotonic() < deadline + 60:
            if micros_rt.is_shutdown():
                break
            pub.publish(fill(data_class(), "warmup", -1, False, 0.0))
            time.sleep(0.05)
        while args.start_file and not os.path.exists(args.start_file) and time.monotonic() < deadline + 60:
            if micros_rt.is_shutdown():
                break
            time.sleep(0.02)
        time.sleep(args.start_delay)
        period = 1.0 / args.rate if args.rate > 0 else 0.0
        start = time.monotonic()
        for i in range(args.count):
            if micros_rt.is_shutdown():
                break
            text = f"{args.prefix} {i}"
            if values is not None:
                msg = set_fields(data_class(), values, i)
                pub.publish(as_numpy(msg) if args.numpy else msg)
            else:
                pub.publish(fill(data_class(), text, i, args.stamp, args.clock_offset))
            emit("sent", seq=i, data=text, connections=pub.get_num_connections())
            next_t = start + (i + 1) * period
            while (left := next_t - time.monotonic()) > 0:
                time.sleep(min(0.005, left))
        end = time.monotonic() + args.linger
        while time.monotonic() < end and not micros_rt.is_shutdown():
            time.sleep(0.02)
        dds_writer = side_writer(pub, "DDS")
        emit("done", connections=pub.get_num_connections(),
             dds_wanted=None if dds_writer is None else bool(dds_writer._writer.wanted),
             statistics=dataclasses_asdict(pub.statistics()),
             shm_not_taken=getattr(side_writer(pub, "SHM"), "not_taken", None))
    else:
        hints = None
        if args.hints:
            hints = micros_rt.TransportHints()
            for h in args.hints.split(","):
                hints = {"shm": hints.shm, "dds": hints.dds}.get(h.strip(), hints.tcp)()

        def on_deadline(info: Any) -> None:
            emit("deadline", silent_for=info.silent_for, total=info.total_count)

        received = [0]

        def cb(msg: Any) -> None:
            _cb(msg)
            received[0] += 1  # after its recv line: --exit-after's "done" never comes before the last "recv"
            if args.callback_sleep:
                time.sleep(args.callback_sleep)

        def _cb(msg: Any) -> None:
            header = getattr(msg, "_connection_header", {}) or {}
            if args.full_msg:
                data = getattr(msg, "data", None)
                emit("recv", data=data if isinstance(data, (str, int, float)) else None, t=time.time(),
                     transport=header.get("transport", "TCPROS"), callerid=header.get("callerid"),
                     msg=full_dict(msg))
                return
            emit("recv", data=getattr(msg, "data", None), t=time.time(),
                 transport=header.get("transport", "TCPROS"), callerid=header.get("callerid"),
                 msg=msg_to_dict(msg) if not hasattr(msg, "data") or not isinstance(msg.data, (str, int)) else None)

        if qos or args.deadline_events or args.with_qos:
            if args.deadline_events:
                qos = dict(qos)
            opts = micros_rt.SubscribeQoSOptions.from_dict(qos)
            if args.deadline_events:
                import dataclasses
                opts = dataclasses.replace(opts, deadline_cb=on_deadline)
            sub = nh.subscribe_with_qos(args.topic, data_class, cb, args.queue_size or None, opts, hints)
        else:
            sub = nh.subscribe(args.topic, data_class, cb, args.queue_size or None, hints)  # 0: None, lossless
        slow = None
        if args.slow_topic:
            def slow_cb(msg: Any) -> None:
                emit("slow_recv", data=getattr(msg, "data", None), t=time.time())
                time.sleep(args.slow_sleep)

            slow = nh.subscribe(args.slow_topic, data_class, slow_cb, 1)
        emit("ready", topic=sub.resolved_name)
        end = time.monotonic() + args.duration
        last_status = 0.0
        while time.monotonic() < end and not micros_rt.is_shutdown():
            if args.exit_after and received[0] >= args.exit_after:
                break
            time.sleep(0.05)
            if time.monotonic() - last_status > 0.5:
                last_status = time.monotonic()
                emit("status", transports=sub.connection_transports(), statistics=dataclasses_asdict(sub.statistics()))
        if slow is not None:
            emit("slow_statistics", **dataclasses_asdict(slow.statistics()))
        emit("done", transports=sub.connection_transports(), latency_count=sub.latency.count,
             statistics=dataclasses_asdict(sub.statistics()),
             latency=sub.latency.summary(), expired=getattr(getattr(sub, "_sub", None), "expired_total", None))
    micros_rt.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
