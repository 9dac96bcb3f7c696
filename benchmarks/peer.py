#!/usr/bin/env python3
"""One benchmark endpoint, run as its own process by benchmarks/run.py.

    python peer.py IMPL ROLE [options]

IMPL:  mrt_shm (micros_rt's default: shared memory between two micros_rt nodes of one host),
       mrt_dds (micros_rt, DDS link, .venv/bin/python), mrt_tcpros (micros_rt, subscriber asks TransportHints().tcp()),
       rospy (stock rospy TCPROS, /usr/bin/python3), cyclone (raw cyclonedds-python, .venv/bin/python),
       rclpy (ROS 2 Jazzy, Fast DDS, .venv-ros2/bin/python)
ROLE:  echo | ping | send | recv | talker | listener | graph

Every role prints JSON lines on stdout (``{"ev": ...}``); the driver reads them. Every role stops by itself
(``--timeout``), on SIGINT/SIGTERM, and when its stdin closes (the driver died).

NB: no ``from __future__ import annotations``: cyclonedds resolves IdlStruct annotations at run time.
"""

import argparse
import array
import json
import os
import signal
import struct
import sys
import threading
import time

_SEQ = struct.Struct("<Q")
STOP = threading.Event()
CMDS = []  # lines read from stdin
CMD_EV = threading.Event()


def emit(ev, **kw):
    sys.stdout.write(json.dumps({"ev": ev, **kw}) + "\n")
    sys.stdout.flush()


def _stdin_reader():
    try:
        for line in sys.stdin:
            CMDS.append(line.strip())
            CMD_EV.set()
    except Exception:
        pass
    STOP.set()  # stdin closed: the driver is gone or done with us
    CMD_EV.set()


def wait_cmd(prefix, timeout):
    deadline = time.monotonic() + timeout
    while True:
        for c in CMDS:
            if c.startswith(prefix):
                return c
        if STOP.is_set() or time.monotonic() > deadline:
            return None
        CMD_EV.wait(0.05)
        CMD_EV.clear()


# =========================================================================== messages

KINDS = ("bytes", "image_vga", "image_hd", "cloud", "scan", "scan_np")


class Msgs:
    """Builds messages of one kind carrying a sequence number, and reads it back."""

    def __init__(self, impl, kind, size):
        self.impl, self.kind, self.size = impl, kind, size
        self.ros2 = impl == "rclpy"
        self.pad = bytes(max(0, size - 8))
        if impl == "cyclone":
            return
        if self.ros2:
            import sensor_msgs.msg as sm
            import std_msgs.msg as stdm
        else:
            import sensor_msgs.msg as sm
            import std_msgs.msg as stdm
        self.cls = {"bytes": stdm.UInt8MultiArray, "image_vga": sm.Image, "image_hd": sm.Image,
                    "cloud": sm.PointCloud2, "scan": sm.LaserScan, "scan_np": sm.LaserScan}[kind]
        if kind == "scan_np" and not self.ros2:  # ROS 1's numpy configuration (rclpy's arrays are array.array)
            from rospy.numpy_msg import numpy_msg
            self.cls = numpy_msg(self.cls)
        self.sm = sm
        if kind == "image_vga":
            self.blob = self._u8(bytes(640 * 480 * 3))
        elif kind == "image_hd":
            self.blob = self._u8(bytes(1920 * 1080 * 3))
        elif kind == "cloud":
            self.blob = self._u8(bytes(65536 * 16))  # 65,536 points x 16 B = 1 MiB
            f = sm.PointField
            self.fields = [f(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")] + \
                [f(name="intensity", offset=12, datatype=7, count=1)]
        elif kind in ("scan", "scan_np"):
            vals = [float(i % 100) / 10.0 for i in range(1081)]
            if self.ros2:
                self.ranges = self.intens = array.array("f", vals)
            elif kind == "scan_np":
                import numpy
                self.ranges = self.intens = numpy.array(vals, dtype=numpy.float32)
            else:
                self.ranges = self.intens = vals

    def _u8(self, b):
        return array.array("B", b) if self.ros2 else b

    def make(self, seq):
        k = self.kind
        if k == "bytes":
            data = _SEQ.pack(seq) + self.pad
            if self.impl == "cyclone":
                return data
            return self.cls(data=self._u8(data))
        m = self.cls()
        m.header.frame_id = str(seq)
        if k.startswith("image"):
            m.height, m.width = (480, 640) if k == "image_vga" else (1080, 1920)
            m.encoding, m.step, m.data = "rgb8", m.width * 3, self.blob
        elif k == "cloud":
            m.height, m.width, m.fields, m.point_step = 1, 65536, self.fields, 16
            m.row_step, m.data, m.is_dense = 65536 * 16, self.blob, True
        else:
            m.angle_min, m.angle_max, m.angle_increment = -2.35, 2.35, 4.7 / 1080
            m.range_min, m.range_max = 0.02, 30.0
            m.ranges, m.intensities = self.ranges, self.intens
        return m

    def seq(self, m):
        if self.kind == "bytes":
            if self.impl == "cyclone":
                return _SEQ.unpack_from(m, 0)[0]
            return _SEQ.unpack_from(m.data, 0)[0]
        return int(m.header.frame_id)


# =========================================================================== transports

class Ros1:
    """micros_rt (DDS or TCPROS fallback) or stock rospy."""

    def __init__(self, impl, name, msgs):
        self.impl, self.msgs = impl, msgs
        self.mrt = impl.startswith("mrt")
        if self.mrt:
            import micros_rt
            self.m = micros_rt
            micros_rt.init_node(name, anonymous=True, disable_signals=True)
            self.nh = micros_rt.NodeHandle()
        else:
            import rospy
            if "micros_rt" in sys.modules:
                raise SystemExit("stock rospy peer must not import micros_rt")
            self.m = rospy
            rospy.init_node(name, anonymous=True, disable_signals=True)

    def pub(self, topic, cls=None):
        cls = cls or self.msgs.cls
        if self.impl == "mrt_budget":  # write batching: samples share datagrams, sent within 0.5 ms
            return self.nh.advertise_with_qos(topic, cls, None, self.m.AdvertiseQoSOptions(latency_budget=0.001))
        if self.mrt:
            return self.nh.advertise(topic, cls, None)
        return self.m.Publisher(topic, cls, queue_size=None, tcp_nodelay=True)

    def sub(self, topic, cb, cls=None):
        cls = cls or self.msgs.cls
        if self.mrt:
            hints = self.m.TransportHints().tcp() if self.impl == "mrt_tcpros" else None
            return self.nh.subscribe(topic, cls, cb, None, hints)
        return self.m.Subscriber(topic, cls, cb, queue_size=None, tcp_nodelay=True)

    def matched(self, p):
        if self.impl in ("mrt_dds", "mrt_budget"):
            return p.get_dds_connections()
        return p.get_num_connections()

    def publish(self, p, m):
        p.publish(m)

    def spin_once(self, t):
        time.sleep(t)

    def close(self):
        try:
            self.m.signal_shutdown("bench done") if not self.mrt else self.m.shutdown("bench done")
        except Exception:
            pass


class Ros2:
    def __init__(self, impl, name, msgs):
        import rclpy
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        self.rclpy, self.msgs = rclpy, msgs
        rclpy.init()
        self.node = rclpy.create_node(name.replace("/", "_") + f"_{os.getpid()}")
        self.retries = 0
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE, depth=1)

    def pub(self, topic, cls=None):
        return self.node.create_publisher(cls or self.msgs.cls, topic, self.qos)

    def sub(self, topic, cb, cls=None):
        return self.node.create_subscription(cls or self.msgs.cls, topic, cb, self.qos)

    def matched(self, p):
        return p.get_subscription_count()

    def publish(self, p, m):
        # Fast DDS refuses a write when a KEEP_ALL history is full ("cannot publish data") instead of
        # blocking: wait for acknowledgements and retry (back-pressure, as the other transports block)
        end = time.monotonic() + 10.0
        while True:
            try:
                p.publish(m)
                return
            except Exception as exc:  # rclpy._rclpy_pybind11.RCLError
                if "cannot publish" not in str(exc) or time.monotonic() > end or STOP.is_set():
                    raise
                self.retries += 1
                self.rclpy.spin_once(self.node, timeout_sec=0.0005)

    def spin_once(self, t):
        self.rclpy.spin_once(self.node, timeout_sec=t)

    def close(self):
        try:
            self.node.destroy_node()
            self.rclpy.shutdown()
        except Exception:
            pass


class Cyclone:
    """Raw cyclonedds-python: struct {sequence<octet> data}, written/taken pre-serialised (ddspy_write/take)."""

    HDR = b"\x00\x01\x00\x00"

    def __init__(self, impl, name, msgs):
        from dataclasses import dataclass

        from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.idl import IdlStruct
        from cyclonedds.idl.types import sequence, uint8
        from cyclonedds.util import duration

        global Bytes_

        @dataclass
        class Bytes_(IdlStruct, typename="bench::Bytes_"):
            data: sequence[uint8]

        self.T = Bytes_
        self.dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
        self.qos = Qos(Policy.Reliability.Reliable(duration(seconds=10)), Policy.History.KeepAll)
        self.any = SampleState.Any | ViewState.Any | InstanceState.Any
        self.WaitSet, self.ReadCondition = WaitSet, ReadCondition
        self.readers = []
        self.ws = WaitSet(self.dp)
        self.msgs = msgs

    def pub(self, topic, cls=None):
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic
        return DataWriter(self.dp, Topic(self.dp, "rt" + topic, self.T), self.qos)

    def sub(self, topic, cb, cls=None):
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        r = DataReader(self.dp, Topic(self.dp, "rt" + topic, self.T), self.qos)
        self.ws.attach(self.ReadCondition(r, self.any))
        self.readers.append((r, cb))
        return r

    def matched(self, p):
        return p.get_publication_matched_status().current_count

    def publish(self, p, m):
        from cyclonedds._clayer import ddspy_write
        ddspy_write(p._ref, self.HDR + struct.pack("<I", len(m)) + m)

    def spin_once(self, t):
        from cyclonedds._clayer import ddspy_take
        self.ws.wait(int(t * 1e9))
        for r, cb in self.readers:
            got = ddspy_take(r._ref, self.any, 256)
            if isinstance(got, int):
                continue
            for data, info in got:
                if info.valid_data:
                    cb(memoryview(data)[8:])

    def close(self):
        pass


def transport(impl, name, msgs):
    if impl == "rclpy":
        return Ros2(impl, name, msgs)
    if impl == "cyclone":
        return Cyclone(impl, name, msgs)
    return Ros1(impl, name, msgs)


def cyclone_echo_payload(m):
    return bytes(m)


# =========================================================================== roles

def wait_matched(tr, p, n, deadline, settle=0.5):
    while tr.matched(p) < n:
        if STOP.is_set() or time.monotonic() > deadline:
            raise SystemExit(f"only {tr.matched(p)} of {n} subscribers matched before the deadline")
        tr.spin_once(0.01)
    # the reader side may still be matching this writer (DDS); same settle time for every transport
    t = time.monotonic() + settle
    while time.monotonic() < t:
        tr.spin_once(0.02)


def parse_specs(a):
    """--specs "kind:size:count:warmup,..." -> list of (kind, size, count, warmup); default from --kind etc."""
    if not a.specs:
        return [(a.kind, a.size, a.count, a.warmup)]
    out = []
    for item in a.specs.split(","):
        k, size, count, warm, *secs = item.split(":")
        out.append((k, int(size), int(count), int(warm)))
        if secs:
            SECONDS[len(out) - 1] = float(secs[0])
    return out


SECONDS = {}  # spec index -> time bound (the 5th field of a spec), else --seconds


def role_echo(a, tr, msgs):
    n = [0]
    keep = []
    for i, (kind, size, _, _) in enumerate(parse_specs(a)):
        m = Msgs(a.impl, kind, size)
        pub = tr.pub(f"{a.topic}_{i}_pong", getattr(m, "cls", None))

        def cb(msg, pub=pub):
            n[0] += 1
            tr.publish(pub, bytes(msg) if a.impl == "cyclone" else msg)

        keep.append(tr.sub(f"{a.topic}_{i}_ping", cb, getattr(m, "cls", None)))
    emit("ready")
    while not STOP.is_set():
        tr.spin_once(0.1)
    emit("done", echoed=n[0])


def role_ping(a, tr, _msgs):
    deadline = time.monotonic() + a.timeout
    threaded = a.impl not in ("rclpy", "cyclone")
    ev = threading.Event()
    want = [-2]
    ents = []
    for i, (kind, size, count, warm) in enumerate(parse_specs(a)):
        msgs = Msgs(a.impl, kind, size)
        pub = tr.pub(f"{a.topic}_{i}_ping", getattr(msgs, "cls", None))

        def cb(m, msgs=msgs):
            if msgs.seq(m) == want[0]:
                ev.set()

        sub = tr.sub(f"{a.topic}_{i}_pong", cb, getattr(msgs, "cls", None))
        ents.append((i, msgs, pub, sub, count, warm))

    def wait(timeout):
        if threaded:
            return ev.wait(timeout)
        end = time.perf_counter() + timeout
        while not ev.is_set():
            rem = end - time.perf_counter()
            if rem <= 0:
                return False
            tr.spin_once(min(rem, 0.05))
        return True

    seq = 0
    for i, msgs, pub, _sub, count, warm in ents:
        wait_matched(tr, pub, 1, deadline, settle=0.0)
        first = False  # resend until the first pong (discovery may still run), then warm-up, then timed
        while not first:
            if STOP.is_set() or time.monotonic() > deadline:
                raise SystemExit(f"no pong on spec {i} before the deadline")
            seq += 1
            want[0] = seq
            ev.clear()
            tr.publish(pub, msgs.make(seq))
            first = wait(0.3)
        rtts, lost = [], 0
        cap = time.monotonic() + SECONDS.get(i, a.seconds)  # per-spec time bound (slow transports / big messages)
        for j in range(warm + count):
            if STOP.is_set() or time.monotonic() > min(deadline, cap):
                break
            seq += 1
            m = msgs.make(seq)
            want[0] = seq
            ev.clear()
            t0 = time.perf_counter()
            tr.publish(pub, m)
            ok = wait(2.0)
            dt = time.perf_counter() - t0
            if j < warm:
                continue
            if ok:
                rtts.append(dt * 1e6)
            else:
                lost += 1
        emit("result", i=i, rtts=rtts, lost=lost)
    emit("done")


def role_send(a, tr, _msgs):
    deadline = time.monotonic() + a.timeout
    for i, (kind, size, count, _) in enumerate(parse_specs(a)):
        msgs = Msgs(a.impl, kind, size)
        pub = tr.pub(f"{a.topic}_{i}", getattr(msgs, "cls", None))
        wait_matched(tr, pub, a.subs, deadline)
        end = time.monotonic() + SECONDS.get(i, a.seconds)
        c0 = time.process_time()
        t0 = time.perf_counter()
        sent = 0
        polled = a.impl == "rclpy"
        while sent < count and not STOP.is_set():
            sent += 1
            tr.publish(pub, msgs.make(sent))
            if (sent & 15) == 0:
                if time.monotonic() > end:
                    break
                if polled:
                    tr.spin_once(0)
        t1 = time.perf_counter()
        cpu = time.process_time() - c0
        emit("sent", i=i, sent=sent, seconds=t1 - t0, cpu_s=cpu, retries=getattr(tr, "retries", 0))
        # stay up (TCPROS/DDS may still be delivering) until the driver says go on
        while not STOP.is_set() and time.monotonic() < deadline:
            if any(c == f"NEXT {i}" for c in CMDS):
                break
            tr.spin_once(0.02)
    while not STOP.is_set() and time.monotonic() < deadline:
        tr.spin_once(0.05)


def role_recv(a, tr, _msgs):
    specs = parse_specs(a)
    lock = threading.Lock()
    state = []
    keep = []
    for i, (kind, size, _, _) in enumerate(specs):
        msgs = Msgs(a.impl, kind, size)
        st = {"seen": set(), "first": None, "last": None}
        state.append(st)

        def cb(m, msgs=msgs, st=st):
            s = msgs.seq(m)
            now = time.perf_counter()
            with lock:
                if s not in st["seen"]:
                    st["seen"].add(s)
                    if st["first"] is None:
                        st["first"] = now
                    st["last"] = now

        keep.append(tr.sub(f"{a.topic}_{i}", cb, getattr(msgs, "cls", None)))
    emit("ready")
    deadline = time.monotonic() + a.timeout
    for i, st in enumerate(state):
        sent = None
        last_n, last_change = 0, time.monotonic()
        while not STOP.is_set() and time.monotonic() < deadline:
            tr.spin_once(0.02)
            if sent is None:
                c = next((c for c in CMDS if c.startswith(f"SENT {i} ")), None)
                if c:
                    sent = int(c.split()[2])
                    last_change = time.monotonic()
            n = len(st["seen"])
            if n != last_n:
                last_n, last_change = n, time.monotonic()
            if sent is not None and (n >= sent or time.monotonic() - last_change > a.drain):
                break
        with lock:
            n = len(st["seen"])
            span = (st["last"] - st["first"]) if n > 1 else None
        emit("result", i=i, received=n, span_s=span, sent=sent)
    while not STOP.is_set() and time.monotonic() < deadline:
        tr.spin_once(0.05)


def role_talker(a, tr, msgs):
    """Spawn-to-first-message and idle memory: publish every 10 ms until IDLE, then idle."""
    pub = tr.pub(a.topic)
    seq = 0
    deadline = time.monotonic() + a.timeout
    while not STOP.is_set() and time.monotonic() < deadline:
        if any(c == "IDLE" for c in CMDS):
            break
        seq += 1
        tr.publish(pub, msgs.make(seq))
        tr.spin_once(0.01)
    emit("idle")
    while not STOP.is_set() and time.monotonic() < deadline:
        tr.spin_once(0.1)


def role_listener(a, tr, msgs):
    first = {}

    def cb(m):
        if not first:
            first["t"] = time.time()

    tr.sub(a.topic, cb)
    emit("ready")
    deadline = time.monotonic() + a.timeout
    while not STOP.is_set() and time.monotonic() < deadline and not first:
        tr.spin_once(0.005)
    emit("first", t=first.get("t"))
    while not STOP.is_set() and time.monotonic() < deadline:
        tr.spin_once(0.1)


def role_graph(a, tr, msgs):
    """Node i of N: publish /g_i at 10 Hz, subscribe to the next three (fewer when N < 4)."""
    n, i = a.nodes, a.index
    others = [(i + k) % n for k in range(1, min(3, n - 1) + 1)]
    heard = set()
    last = {}  # j -> the last sequence number heard from node j
    count = {"lost": 0, "recv": 0}

    def mk(j):
        def cb(m):
            heard.add(j)
            seq = msgs.seq(m)
            before = last.get(j)
            if before is not None and seq > before + 1:
                count["lost"] += seq - before - 1  # every message missing once node j was heard
            last[j] = seq
            count["recv"] += 1
        return cb

    pub = tr.pub(f"{a.topic}_{i}")
    subs = [tr.sub(f"{a.topic}_{j}", mk(j)) for j in others]
    service = None
    if a.service and i == 0:  # one node of the graph offers a std_srvs/Trigger (micros_rt: to ROS 2 as well)
        from std_srvs.srv import Trigger, TriggerResponse

        answer = lambda _req: TriggerResponse(success=True, message="ok")  # noqa: E731
        if a.impl.startswith("mrt"):
            import micros_rt

            service = micros_rt.NodeHandle().advertise_service(f"{a.topic}_trigger", Trigger, answer)
        else:
            import rospy

            service = rospy.Service(f"{a.topic}_trigger", Trigger, answer)
        emit("service", ros2_error=getattr(service, "ros2_error", None))
    deadline = time.monotonic() + a.timeout
    seq, nxt, told, asked = 0, time.monotonic(), False, 0
    while not STOP.is_set() and time.monotonic() < deadline:
        if len(CMDS) > asked:  # "STATS": what this node heard and lost so far
            asked = len(CMDS)
            emit("stats", recv=count["recv"], lost=count["lost"])
        now = time.monotonic()
        if now >= nxt:
            seq += 1
            tr.publish(pub, msgs.make(seq))
            nxt += 0.1
        if not told and len(heard) == len(others):
            told = True
            emit("connected", t=time.time())
        tr.spin_once(max(0.0, min(0.05, nxt - time.monotonic())))
    if not told:
        emit("not_connected", heard=sorted(heard), want=others)
    del subs, service


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("impl", choices=("mrt_shm", "mrt_dds", "mrt_budget", "mrt_tcpros", "rospy", "cyclone", "rclpy"))
    ap.add_argument("role", choices=("echo", "ping", "send", "recv", "talker", "listener", "graph"))
    ap.add_argument("--topic", default="/bench")
    ap.add_argument("--kind", default="bytes", choices=KINDS)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--specs", default="", help="kind:size:count:warmup,... (several topics in one process)")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--subs", type=int, default=1)
    ap.add_argument("--drain", type=float, default=2.0)
    ap.add_argument("--nodes", type=int, default=2)
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--service", action="store_true", help="graph: node 0 also offers a std_srvs/Trigger")
    ap.add_argument("--timeout", type=float, default=60.0)
    a = ap.parse_args()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.set())
    threading.Thread(target=_stdin_reader, daemon=True).start()
    code = 0
    tr = None
    try:
        msgs = Msgs(a.impl, a.kind, a.size)
        tr = transport(a.impl, f"bench_{a.role}", msgs)
        globals()["role_" + a.role](a, tr, msgs)
    except SystemExit as exc:
        emit("error", error=str(exc.code))
        code = 1
    except BaseException as exc:
        emit("error", error=f"{type(exc).__name__}: {exc}")
        code = 1
    finally:
        sys.stdout.flush()
        if tr is not None and a.impl != "cyclone":
            t = threading.Thread(target=tr.close, daemon=True)
            t.start()
            t.join(2.0)
        os._exit(code)


if __name__ == "__main__":
    main()
