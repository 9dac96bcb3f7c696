"""ROS 2 (rclpy, Fast DDS) peer for tests. Run ONLY with .venv-ros2/bin/python (never with rospy around).

Environment (the harness sets it): ROS_DOMAIN_ID, FASTRTPS_DEFAULT_PROFILES_FILE=tests/peers/fastdds_loopback.xml,
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, so nothing leaves on the LAN.

Subcommands (one JSON object per stdout line):
  talk    {"event":"ready"}, {"event":"matched","n"} on subscriber-count change,
          {"event":"sent","seq","data","msg"[,"stamp"]} per message, {"event":"done","sent"}
  listen  {"event":"ready"}, {"event":"matched","n"} on publisher-count change,
          {"event":"recv","seq","data","msg","t"[,"stamp"]} per message, {"event":"done","received"}
  info    {"event":"info","topic","publishers":[...],"subscriptions":[...]} with each endpoint's
          node name, type and QoS (reliability, durability, history, depth, deadline_ns, lifespan_ns, liveliness)

"data" is the value of a message's single ``data`` field (std_msgs/msg/String, Int32, ...), else the full dict.
"stamp" is {"secs","nsecs"} for messages with a header (ROS 2 Header has sec/nanosec and no seq).
With --full-msg, "msg" holds every field and uint8[] fields print as {"bytes_len","sha256","head"}
(set_fields/--data-json accept {"$bytes": {"len": N, "seed": S}} for them).
"""

from __future__ import annotations

import argparse
import array
import hashlib
import importlib
import json
import re
import sys
import time
from typing import Any, Dict, List, Optional, Tuple

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}, default=str) + "\n")
    sys.stdout.flush()


def msg_class(type_name: str) -> Any:
    """'std_msgs/msg/String' (or 'std_msgs/String') -> class."""
    parts = type_name.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3:
        raise SystemExit(f"bad type {type_name!r}, want pkg/msg/Type")
    return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])


def to_dict(value: Any) -> Any:
    """rclpy message -> JSON-friendly value (rosidl_runtime_py's converter when installed)."""
    if hasattr(value, "get_fields_and_field_types"):
        try:
            from rosidl_runtime_py.convert import message_to_ordereddict  # type: ignore[import-not-found]
            return json.loads(json.dumps(message_to_ordereddict(value), default=_plain))
        except ImportError:
            pass
        return {f: to_dict(getattr(value, f)) for f in value.get_fields_and_field_types()}
    return _plain(value)


def _plain(value: Any) -> Any:
    if hasattr(value, "get_fields_and_field_types"):
        return to_dict(value)
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, array.array):
        return value.tolist()
    if hasattr(value, "tolist"):  # numpy arrays / scalars
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


_BYTE_ELEMS = ("uint8", "octet", "char", "byte")


def pattern_bytes(n: int, seed: int) -> bytes:
    """Deterministic test payload; the same function lives in mrt_peer.py and the interop tests."""
    base = bytes((seed + 7 * k) & 0xFF for k in range(256))
    return (base * (n // 256 + 1))[:n]


def bytes_summary(data: bytes) -> Dict[str, Any]:
    """How both test peers print uint8[] fields: length, sha256 and the first 8 bytes."""
    return {"bytes_len": len(data), "sha256": hashlib.sha256(data).hexdigest(), "head": list(data[:8])}


def _elem_type(field_type: str) -> Tuple[str, bool]:
    """'sequence<sensor_msgs/PointField>' -> ('sensor_msgs/PointField', True); 'double[9]' -> ('double', True)."""
    if field_type.startswith("sequence<"):
        inner = field_type[len("sequence<"):].split(">")[0].split(",")[0]
        return inner, True
    if field_type.endswith("]"):
        return field_type.split("[")[0], True
    return field_type, False


def _is_bytes_field(field_type: str) -> bool:
    elem, is_array = _elem_type(field_type)
    return is_array and elem in _BYTE_ELEMS


def set_fields(msg: Any, values: Dict[str, Any], i: int) -> None:
    """Set fields from a dict (nested dicts for nested messages); '{i}' in strings becomes the sequence number.

    Lists of dicts fill message arrays; ``{"$bytes": {"len": N, "seed": S}}`` fills a uint8[] field with
    :func:`pattern_bytes` (a 640x480 image does not fit on a command line).
    """
    types = msg.get_fields_and_field_types()
    for key, val in values.items():
        if key not in types:
            raise SystemExit(f"{type(msg).__name__} has no field {key!r}")
        cur = getattr(msg, key)
        elem, is_array = _elem_type(types[key])
        if isinstance(val, dict) and "$bytes" in val:
            spec = val["$bytes"]
            setattr(msg, key, array.array("B", pattern_bytes(int(spec["len"]), int(spec.get("seed", 0)))))
        elif isinstance(val, dict) and hasattr(cur, "get_fields_and_field_types"):
            set_fields(cur, val, i)
        elif elem == "octet" and not is_array and isinstance(val, int):
            setattr(msg, key, bytes([val]))   # rclpy holds a byte as bytes of length 1
        elif isinstance(val, list) and is_array and "/" in elem:
            cls = msg_class(elem)
            items = []
            for v in val:
                item = cls()
                set_fields(item, v, i)
                items.append(item)
            setattr(msg, key, items)
        else:
            if isinstance(val, str):
                val = val.replace("{i}", str(i))
            if is_array and elem in _BYTE_ELEMS and isinstance(val, list):
                val = array.array("B", val) if types[key].startswith("sequence") else val
            setattr(msg, key, val)


def full_dict(msg: Any) -> Any:
    """Every field of an rclpy message, uint8[] fields as :func:`bytes_summary` (--full-msg)."""
    out: Dict[str, Any] = {}
    for name, ftype in msg.get_fields_and_field_types().items():
        val = getattr(msg, name)
        if _is_bytes_field(ftype):
            out[name] = bytes_summary(bytes(bytearray(val)) if not isinstance(val, bytes) else val)
        elif hasattr(val, "get_fields_and_field_types"):
            out[name] = full_dict(val)
        elif isinstance(val, (list, tuple)) and val and hasattr(val[0], "get_fields_and_field_types"):
            out[name] = [full_dict(v) for v in val]
        else:
            out[name] = _plain(val)
    return out


def fill(msg: Any, i: int, prefix: str, node: Any) -> None:
    fields = msg.get_fields_and_field_types()
    t = fields.get("data")
    if t == "string":
        msg.data = f"{prefix} {i}"
    elif t == "boolean":
        msg.data = bool(i % 2)
    elif t in ("float", "double"):
        msg.data = float(i)
    elif t in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "octet"):
        msg.data = i
    header = msg if type(msg).__name__ == "Header" else getattr(msg, "header", None)
    if header is not None and hasattr(header, "stamp"):
        header.stamp = node.get_clock().now().to_msg()
        header.frame_id = prefix
    pose = getattr(msg, "pose", None)
    if pose is not None and hasattr(pose, "position"):
        pose.position.x = float(i)
        pose.orientation.w = 1.0


def summary(msg: Any, full_msg: bool = False) -> Tuple[Any, Dict[str, Any]]:
    full = full_dict(msg) if full_msg else to_dict(msg)
    data = full["data"] if list(full) == ["data"] else full
    extra: Dict[str, Any] = {"msg": full}
    header = msg if type(msg).__name__ == "Header" else getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None) if header is not None else None
    if stamp is not None and hasattr(stamp, "nanosec"):
        extra["stamp"] = {"secs": int(stamp.sec), "nsecs": int(stamp.nanosec)}
    return data, extra


def qos_from_args(args: argparse.Namespace) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=args.depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if args.reliability == "best_effort" else ReliabilityPolicy.RELIABLE,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if args.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE),
    )


def _policy_name(p: Any) -> str:
    name = getattr(p, "name", str(p))
    return str(name).lower()


def _duration_ns(d: Any) -> int:
    return int(getattr(d, "nanoseconds", 0))


def endpoint_info(e: Any) -> Dict[str, Any]:
    q = e.qos_profile
    return {
        "node_name": e.node_name,
        "node_namespace": e.node_namespace,
        "topic_type": e.topic_type,
        "endpoint_type": _policy_name(e.endpoint_type),
        "qos": {
            "reliability": _policy_name(q.reliability),
            "durability": _policy_name(q.durability),
            "history": _policy_name(q.history),
            "depth": int(q.depth),
            "deadline_ns": _duration_ns(q.deadline),
            "lifespan_ns": _duration_ns(q.lifespan),
            "liveliness": _policy_name(q.liveliness),
            "liveliness_lease_duration_ns": _duration_ns(q.liveliness_lease_duration),
        },
    }


class Runner:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.t_end = time.monotonic() + args.duration
        self.node = rclpy.create_node(args.node_name or f"ros2_peer_{args.cmd}")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def spin_once(self, timeout: float = 0.01) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def time_left(self) -> bool:
        return bool(time.monotonic() < self.t_end)

    def talk(self) -> int:
        a = self.args
        cls = msg_class(a.type)
        pub = self.node.create_publisher(cls, a.topic, qos_from_args(a))
        emit("ready", node=self.node.get_fully_qualified_name(), topic=pub.topic_name)
        values: Optional[Dict[str, Any]] = json.loads(a.data_json) if a.data_json else None
        last_n = -1

        def poll() -> int:
            nonlocal last_n
            n = pub.get_subscription_count()
            if n != last_n:
                last_n = n
                emit("matched", n=n)
            return int(n)

        if a.wait_subscribers > 0:
            deadline = min(time.monotonic() + a.wait_timeout, self.t_end)
            while poll() < a.wait_subscribers:
                if time.monotonic() > deadline:
                    emit("error", what=f"timed out waiting for {a.wait_subscribers} subscribers")
                    return 3
                self.spin_once(0.01)
        period = 1.0 / a.rate if a.rate > 0 else 0.0
        next_t = time.monotonic()
        sent = 0
        while self.time_left() and (a.count == 0 or sent < a.count):
            msg = cls()
            if values is not None:
                set_fields(msg, values, sent)
            else:
                fill(msg, sent, a.prefix, self.node)
            pub.publish(msg)
            data, extra = summary(msg, a.full_msg)
            emit("sent", seq=sent, data=data, t=time.time(), **extra)
            sent += 1
            poll()
            if period:
                next_t += period
                while True:
                    left = next_t - time.monotonic()
                    if left <= 0:
                        break
                    self.spin_once(min(left, 0.05))
        linger_end = min(time.monotonic() + a.linger, self.t_end)
        while time.monotonic() < linger_end:
            poll()
            self.spin_once(0.02)
        emit("done", sent=sent)
        return 0

    def listen(self) -> int:
        a = self.args
        cls = msg_class(a.type)
        received = 0

        def callback(msg: Any) -> None:
            nonlocal received
            t = time.time()
            data, extra = summary(msg, a.full_msg)
            emit("recv", seq=received, data=data, t=t, **extra)
            received += 1

        sub = self.node.create_subscription(cls, a.topic, callback, qos_from_args(a))
        emit("ready", node=self.node.get_fully_qualified_name(), topic=sub.topic_name)
        last_n = -1
        while self.time_left() and (a.count == 0 or received < a.count):
            n = sub.get_publisher_count()
            if n != last_n:
                last_n = n
                emit("matched", n=n)
            self.spin_once(0.02)
        emit("done", received=received)
        return 0

    def info(self) -> int:
        a = self.args
        emit("ready", node=self.node.get_fully_qualified_name(), topic=a.topic)
        deadline = min(time.monotonic() + a.wait, self.t_end)
        pubs: List[Any] = []
        subs: List[Any] = []
        while True:
            pubs = self.node.get_publishers_info_by_topic(a.topic)
            subs = self.node.get_subscriptions_info_by_topic(a.topic)
            enough = len(pubs) >= a.min_publishers and len(subs) >= a.min_subscriptions
            if a.wait_node:  # also wait until ROS 2's graph names that node (ros_discovery_info)
                named = {e.node_name for e in pubs + subs}
                enough = enough and set(a.wait_node.split(",")) <= named
            if a.node_count:  # "REGEX:N": until exactly N node names match REGEX
                pattern, _, n = a.node_count.rpartition(":")
                names = [name for name, _ns in self.node.get_node_names_and_namespaces()]
                enough = enough and sum(1 for name in names if re.search(pattern, name)) == int(n)
            if (enough and (a.min_publishers or a.min_subscriptions or a.wait_node or a.node_count)) \
                    or time.monotonic() >= deadline:
                break
            self.spin_once(0.05)
        emit("info", topic=a.topic, publishers=[endpoint_info(e) for e in pubs],
             subscriptions=[endpoint_info(e) for e in subs],
             nodes=[[ns, name] for name, ns in self.node.get_node_names_and_namespaces()])
        return 0


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser()
    sp = ap.add_subparsers(dest="cmd", required=True)
    for cmd in ("talk", "listen", "info"):
        p = sp.add_parser(cmd)
        p.add_argument("--topic", default="/chatter")
        p.add_argument("--node-name", default=None)
        p.add_argument("--duration", type=float, default=30.0, help="hard upper bound on run time, seconds")
        if cmd in ("talk", "listen"):
            p.add_argument("--type", default="std_msgs/msg/String")
            p.add_argument("--count", type=int, default=10 if cmd == "talk" else 0,
                           help="messages to send / receive before exiting (0 = until --duration)")
            p.add_argument("--reliability", choices=["reliable", "best_effort"], default="reliable")
            p.add_argument("--durability", choices=["volatile", "transient_local"], default="volatile")
            p.add_argument("--depth", type=int, default=10)
            p.add_argument("--full-msg", action="store_true",
                           help="print every field, uint8[] fields as {bytes_len, sha256, head}")
        if cmd == "talk":
            p.add_argument("--rate", type=float, default=10.0, help="Hz (0 = as fast as possible)")
            p.add_argument("--prefix", default="hello")
            p.add_argument("--data-json", default=None,
                           help='fields to set, e.g. \'{"data": "x {i}"}\' ({i} = sequence number)')
            p.add_argument("--wait-subscribers", type=int, default=0)
            p.add_argument("--wait-timeout", type=float, default=20.0)
            p.add_argument("--linger", type=float, default=0.0)
        if cmd == "info":
            p.add_argument("--wait", type=float, default=2.0,
                           help="seconds of discovery before printing (less once the --min-* counts are seen)")
            p.add_argument("--min-publishers", type=int, default=0)
            p.add_argument("--min-subscriptions", type=int, default=0)
            p.add_argument("--wait-node", default="",
                           help="also wait until endpoints are attributed to these node names (comma list)")
            p.add_argument("--node-count", default="",
                           help="REGEX:N, also wait until exactly N node names of the graph match REGEX")
    args = ap.parse_args(argv)

    rclpy.init()
    runner: Optional[Runner] = None
    try:
        runner = Runner(args)
        return int(getattr(runner, args.cmd)())
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if runner is not None:
            runner.executor.shutdown(timeout_sec=1.0)
            runner.node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main())
