#!/usr/bin/env python3
"""micros_rt DDS vs raw cyclonedds-python vs stock rospy TCPROS, between two processes on loopback.

One run measures, for each implementation:

* ping-pong round trip latency (median, p90, p99) with 64 B and 64 KiB std_msgs/String payloads;
* one-way throughput (messages/s and MB/s received, reliable, KEEP_LAST) with 64 B and 1 MiB payloads.

Implementations:

* ``mrt``  micros_rt.NodeHandle advertise/subscribe; the run asserts the link is DDS;
* ``dds``  raw cyclonedds-python, hand-written IdlStruct, DataWriter.write / WaitSet + DataReader.take;
* ``ros``  stock rospy Publisher/Subscriber (TCPROS), run by /usr/bin/python3 without micros_rt.

Usage:  .venv/bin/python benchmarks/bench.py [--quick] [--json FILE] [--impls mrt,dds,ros]

The script starts its own rosmaster on a free port and stops it; every child gets ROS_IP=127.0.0.1,
a random ROS_DOMAIN_ID in 100..200 and CYCLONEDDS_URI -> tests/cyclonedds_loopback.xml (DDS stays on
loopback; the eth0 tx packet delta is printed). Every phase is time-bounded and every child is stopped
(SIGINT, then SIGTERM, then SIGKILL).

NB: no ``from __future__ import annotations`` here: cyclonedds resolves IdlStruct annotations at run time.
"""

import argparse
import json
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import xmlrpc.client
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
VENV_PY = str(REPO / ".venv" / "bin" / "python")
STOCK_PY = "/usr/bin/python3"
CYCLONE_XML = REPO / "tests" / "cyclonedds_loopback.xml"
ETH0_TX = Path("/sys/class/net/eth0/statistics/tx_packets")
KiB = 1024
MiB = 1024 * 1024
SEQ_DIGITS = 10
IMPLS = ("mrt", "dds", "ros")
IMPL_NAMES = {"mrt": "micros_rt DDS", "dds": "raw cyclonedds-py", "ros": "rospy TCPROS"}


# =========================================================================== child side (shared)

def _payload(seq, size):
    # std_msgs/String data of exactly ``size`` bytes; the first digits carry the sequence number
    return f"{seq:0{SEQ_DIGITS}d}" + "x" * (size - SEQ_DIGITS)


def _seq(data):
    return int(data[:SEQ_DIGITS])


def _result(obj):
    sys.stdout.write("RESULT " + json.dumps(obj) + "\n")
    sys.stdout.flush()


def _percentiles(rtts):
    s = sorted(rtts)
    n = len(s)

    def pct(p):
        return s[min(n - 1, int(round(p / 100.0 * (n - 1))))]

    return {"n": n, "median_us": statistics.median(s) * 1e6, "p90_us": pct(90) * 1e6,
            "p99_us": pct(99) * 1e6, "min_us": s[0] * 1e6, "mean_us": statistics.fmean(s) * 1e6}


class _Stop:
    """Set by SIGINT/SIGTERM (raw DDS children) or rospy shutdown, and by the child's own deadline."""

    def __init__(self, timeout):
        self.deadline = time.monotonic() + timeout
        self.flag = False

    def __call__(self):
        return self.flag or time.monotonic() > self.deadline


class _Waiter:
    """Callback side of a ping: wakes the pinging thread when the expected pong arrives."""

    def __init__(self):
        self.ev = threading.Event()
        self.expect = -1
        self.non_dds = 0
        self.got = 0

    def on_msg(self, msg):
        self.got += 1
        hdr = getattr(msg, "_connection_header", None) or {}
        if hdr.get("transport", "TCPROS") != "DDS":
            self.non_dds += 1
        if _seq(msg.data) == self.expect:
            self.ev.set()


def _ping_loop(args, send, wait, stop):
    """Warm-up (resending until pongs flow), then ``args.count`` timed round trips."""
    seq = 0
    got_first = False
    t_first = time.monotonic()
    while not got_first:  # discovery / negotiation may still be going on: resend
        if stop():
            raise SystemExit("no pong before the deadline")
        seq += 1
        send(seq, seq_only=True)
        got_first = wait(seq, 0.25)
    first_s = time.monotonic() - t_first
    for _ in range(args.warmup):
        seq += 1
        send(seq, seq_only=True)
        if not wait(seq, 2.0):
            raise SystemExit(f"warm-up ping {seq} lost")
    rtts = []
    lost = 0
    for _ in range(args.count):
        if stop():
            raise SystemExit("deadline hit during the timed round trips")
        seq += 1
        rt = send(seq)
        if rt is None:
            lost += 1
            continue
        rtts.append(rt)
    return rtts, lost, first_s


# =========================================================================== raw cyclonedds

_RAW_TYPE = None


def _raw_string_type():
    # A hand-written std_msgs/String as a ROS 2 node would announce it. Defined at module level
    # (the binding resolves annotations through the module), only in the raw-DDS child
    # (/usr/bin/python3 has no cyclonedds).
    global _RAW_TYPE
    if _RAW_TYPE is None:
        from dataclasses import dataclass

        from cyclonedds.idl import IdlStruct

        @dataclass
        class String_(IdlStruct, typename="std_msgs::msg::dds_::String_"):
            data: str

        _RAW_TYPE = String_
    return _RAW_TYPE


def _dds_entities(args, role):
    from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    String_ = _raw_string_type()
    dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(args.depth))

    def topic(name):
        return Topic(dp, "rt/" + name.lstrip("/"), String_)

    ws = WaitSet(dp)
    any_state = SampleState.Any | ViewState.Any | InstanceState.Any
    ents = {"dp": dp, "String_": String_, "ws": ws}
    if role in ("lat-ping", "lat-echo"):
        wname, rname = (args.topic + "_ping", args.topic + "_pong")
        if role == "lat-echo":
            wname, rname = rname, wname
        ents["writer"] = DataWriter(dp, topic(wname), qos)
        ents["reader"] = DataReader(dp, topic(rname), qos)
    elif role == "tp-send":
        ents["writer"] = DataWriter(dp, topic(args.topic), qos)
    else:
        ents["reader"] = DataReader(dp, topic(args.topic), qos)
    if "reader" in ents:
        ents["rc"] = ReadCondition(ents["reader"], any_state)
        ws.attach(ents["rc"])
    return ents


def _dds_wait_matched(writer, stop):
    while writer.get_publication_matched_status().current_count < 1:
        if stop():
            raise SystemExit("no matched reader before the deadline")
        time.sleep(0.01)


def dds_child(args, stop):
    def on_signal(*_):
        stop.flag = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    e = _dds_entities(args, args.role)
    String_, ws = e["String_"], e["ws"]
    if args.role == "lat-ping":
        writer, reader = e["writer"], e["reader"]
        _dds_wait_matched(writer, stop)

        def wait(seq, timeout):
            deadline = time.perf_counter() + timeout
            while True:
                for s in reader.take(N=64):
                    if _seq(s.data) == seq:
                        return True
                rem = deadline - time.perf_counter()
                if rem <= 0:
                    return False
                ws.wait(int(rem * 1e9))

        def send(seq, seq_only=False):
            msg = String_(data=_payload(seq, args.size))
            t0 = time.perf_counter()
            writer.write(msg)
            if seq_only:
                return None
            if not wait(seq, 2.0):
                return None
            return time.perf_counter() - t0

        rtts, lost, first_s = _ping_loop(args, send, wait, stop)
        _result({"ok": True, **_percentiles(rtts), "lost": lost, "first_pong_s": first_s, "transport": "DDS"})
    elif args.role == "lat-echo":
        writer, reader = e["writer"], e["reader"]
        n = 0
        while not stop():
            ws.wait(200_000_000)
            for s in reader.take(N=64):
                writer.write(s)
                n += 1
        _result({"ok": True, "echoed": n})
    elif args.role == "tp-send":
        writer = e["writer"]
        _dds_wait_matched(writer, stop)
        seq = 0
        size = args.size
        while not stop():
            seq += 1
            writer.write(String_(data=_payload(seq, size)))
        _result({"ok": True, "sent": seq})
    else:  # tp-recv
        reader = e["reader"]
        st = _TpStats(args)
        while not stop() and not st.done:
            ws.wait(200_000_000)
            for s in reader.take(N=256):
                st.count += 1
                st.last_seq = _seq(s.data)
            st.tick()
        st.report(stop, transport="DDS")


class _TpStats:
    """Received-message counter with a warm-up and a measurement window (monotonic clock)."""

    def __init__(self, args):
        self.args = args
        self.count = 0
        self.last_seq = 0
        self.first = None
        self.t0 = self.t1 = None
        self.c0 = self.c1 = self.s0 = self.s1 = 0
        self.done = False

    def tick(self):
        if self.count == 0 or self.done:
            return
        now = time.perf_counter()
        if self.first is None:
            self.first = now
        elif self.t0 is None and now - self.first >= self.args.warmup_s:
            self.t0, self.c0, self.s0 = now, self.count, self.last_seq
        elif self.t0 is not None and now - self.t0 >= self.args.window_s:
            self.t1, self.c1, self.s1 = now, self.count, self.last_seq
            self.done = True

    def report(self, stop, **extra):
        if not self.done:
            raise SystemExit(f"window not completed before the deadline (received {self.count})")
        dt = self.t1 - self.t0
        n = self.c1 - self.c0
        rate = n / dt
        _result({"ok": True, "msgs": n, "seconds": dt, "msg_per_s": rate,
                 "MB_per_s": rate * self.args.size / 1e6,
                 "lost_in_window": max(0, (self.s1 - self.s0) - n), **extra})


# =========================================================================== rospy / micros_rt

def ros_child(args, stop, use_mrt):
    from std_msgs.msg import String

    if use_mrt:
        import micros_rt

        micros_rt.init_node(f"bench_{args.role.replace('-', '_')}", anonymous=True)
        nh = micros_rt.NodeHandle()

        def is_shutdown():
            return micros_rt.is_shutdown()

        def advertise(name):
            return nh.advertise(name, String, args.depth)

        def subscribe(name, cb):
            return nh.subscribe(name, String, cb, queue_size=args.depth)

        def shutdown():
            micros_rt.shutdown("bench done")
    else:
        import rospy

        if "micros_rt" in sys.modules:
            raise SystemExit("the stock rospy child must not import micros_rt")
        rospy.init_node(f"bench_{args.role.replace('-', '_')}", anonymous=True)

        def is_shutdown():
            return rospy.is_shutdown()

        def advertise(name):
            return rospy.Publisher(name, String, queue_size=args.depth)

        def subscribe(name, cb):
            return rospy.Subscriber(name, String, cb, queue_size=args.depth)

        def shutdown():
            rospy.signal_shutdown("bench done")

    def stopped():
        return stop() or is_shutdown()

    def wait_pub_ready(pub):
        while True:
            if stopped():
                raise SystemExit("no subscriber connected before the deadline")
            if use_mrt:
                if pub.get_dds_connections() >= 1:
                    return
            elif pub.get_num_connections() >= 1:
                return
            time.sleep(0.01)

    def transports(sub):
        if use_mrt:
            return sorted(set(sub.connection_transports().values()))
        return ["TCPROS"]

    try:
        if args.role == "lat-ping":
            w = _Waiter()
            pub = advertise(args.topic + "_ping")
            sub = subscribe(args.topic + "_pong", w.on_msg)
            wait_pub_ready(pub)

            def wait(seq, timeout):
                return w.ev.wait(timeout)

            def send(seq, seq_only=False):
                msg = String(data=_payload(seq, args.size))
                w.expect = seq
                w.ev.clear()
                t0 = time.perf_counter()
                pub.publish(msg)
                if seq_only:
                    return None
                if not w.ev.wait(2.0):
                    return None
                return time.perf_counter() - t0

            rtts, lost, first_s = _ping_loop(args, send, wait, stopped)
            tr = transports(sub)
            res = {"ok": True, **_percentiles(rtts), "lost": lost, "first_pong_s": first_s,
                   "transport": "+".join(tr), "non_dds_msgs": w.non_dds if use_mrt else None}
            if use_mrt and (tr != ["DDS"] or w.non_dds):
                res["ok"] = False
                res["error"] = f"micros_rt link is not DDS: transports {tr}, {w.non_dds} non-DDS pongs"
            _result(res)
        elif args.role == "lat-echo":
            pub = advertise(args.topic + "_pong")
            counts = {"n": 0, "non_dds": 0}

            def echo(msg):
                counts["n"] += 1
                if use_mrt and msg._connection_header.get("transport") != "DDS":
                    counts["non_dds"] += 1
                pub.publish(msg)

            sub = subscribe(args.topic + "_ping", echo)
            seen = []  # transports while running (rospy drops the links on shutdown)
            while not stopped():
                time.sleep(0.05)
                seen = transports(sub) or seen
            _result({"ok": True, "echoed": counts["n"], "non_dds": counts["non_dds"], "transport": seen})
        elif args.role == "tp-send":
            pub = advertise(args.topic)
            wait_pub_ready(pub)
            seq = 0
            size = args.size
            while not stopped():
                seq += 1
                pub.publish(String(data=_payload(seq, size)))
            _result({"ok": True, "sent": seq})
        else:  # tp-recv
            st = _TpStats(args)
            hdr = {}

            def on_msg(msg):
                if not hdr:
                    hdr.update(getattr(msg, "_connection_header", None) or {})
                st.count += 1
                st.last_seq = _seq(msg.data)

            sub = subscribe(args.topic, on_msg)
            while not stopped() and not st.done:
                time.sleep(0.002)
                st.tick()
            tr = transports(sub)
            first_tr = hdr.get("transport", "TCPROS")
            if use_mrt and (tr != ["DDS"] or first_tr != "DDS"):
                _result({"ok": False, "error": f"micros_rt link is not DDS: {tr}, first message {first_tr}"})
            else:
                st.report(stopped, transport="+".join(tr))
    finally:
        shutdown()


# =========================================================================== child entry

def child_main(args):
    stop = _Stop(args.timeout)
    prof = None
    instrument = None
    if os.environ.get("BENCH_INSTRUMENT") and args.impl in ("mrt", "dds"):
        sys.path.insert(0, str(HERE))
        import instrument

        instrument.install() if args.impl == "mrt" else instrument.install_dds()
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    try:
        if args.impl == "dds":
            dds_child(args, stop)
        else:
            ros_child(args, stop, use_mrt=(args.impl == "mrt"))
    except SystemExit as exc:
        if exc.code not in (None, 0):
            _result({"ok": False, "error": str(exc.code)})
    except BaseException as exc:  # report, never hang
        _result({"ok": False, "error": f"{type(exc).__name__}: {exc}"})
    finally:
        if instrument is not None:
            instrument.report()
        if prof is not None:
            prof.disable()
            prof.dump_stats(args.profile)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)  # no lingering non-daemon threads


# =========================================================================== parent side

def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def eth0_tx():
    try:
        return int(ETH0_TX.read_text().strip())
    except OSError:
        return None


def stop_proc(proc, grace=3.0):
    """SIGINT, then SIGTERM, then SIGKILL, each waiting at most ``grace`` seconds."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        if proc.poll() is not None:
            break
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(grace)
        except subprocess.TimeoutExpired:
            continue
    return proc.poll()


class Child:
    def __init__(self, python, argv, env, log_dir, name):
        self.name = name
        self.out = open(log_dir / f"{name}.out", "w+")
        self.err = open(log_dir / f"{name}.err", "w+")
        self.proc = subprocess.Popen([python, str(Path(__file__).resolve()), *argv], env=env,
                                     stdout=self.out, stderr=self.err, stdin=subprocess.DEVNULL)

    def result(self):
        self.out.flush()
        self.out.seek(0)
        res = None
        for line in self.out.read().splitlines():
            if line.startswith("RESULT "):
                res = json.loads(line[7:])
        return res

    def stderr_tail(self, n=6):
        self.err.flush()
        self.err.seek(0)
        return "\n".join(self.err.read().splitlines()[-n:])



def run_phase(impl, kind, size, cfg, env, log_dir, profile_dir):
    python = STOCK_PY if impl == "ros" else VENV_PY
    tag = f"{impl}_{kind}_{size}"
    topic = f"/bench_{tag}_{random.randrange(1 << 30)}"
    depth = cfg["depth_small"] if size <= 64 * KiB else cfg["depth_large"]
    if kind == "lat":
        count = cfg["lat_count_small"] if size <= 64 else cfg["lat_count_large"]
        warm = max(20, count // 10)
        limit = 40.0 + count * 0.02
        common = ["--impl", impl, "--topic", topic, "--size", str(size), "--depth", str(depth),
                  "--timeout", str(limit)]
        driver_argv = ["--role", "lat-ping", "--count", str(count), "--warmup", str(warm)]
        peer_argv = ["--role", "lat-echo"]
    else:
        limit = 40.0 + cfg["tp_warmup"] + cfg["tp_window"]
        common = ["--impl", impl, "--topic", topic, "--size", str(size), "--depth", str(depth),
                  "--timeout", str(limit)]
        driver_argv = ["--role", "tp-recv", "--warmup-s", str(cfg["tp_warmup"]), "--window-s", str(cfg["tp_window"])]
        peer_argv = ["--role", "tp-send"]

    def prof(name):
        if profile_dir and impl in profile_dir[1]:
            return ["--profile", str(Path(profile_dir[0]) / f"{tag}_{name}.prof")]
        return []

    peer = Child(python, ["--child", *common, *peer_argv, *prof("peer")], env, log_dir, f"{tag}_peer")
    driver = Child(python, ["--child", *common, *driver_argv, *prof("driver")], env, log_dir, f"{tag}_driver")
    t0 = time.monotonic()
    try:
        try:
            driver.proc.wait(limit + 5.0)
        except subprocess.TimeoutExpired:
            pass
        res = driver.result()
    finally:
        stop_proc(driver.proc)
        stop_proc(peer.proc)
    peer_res = peer.result()
    if res is None:
        res = {"ok": False, "error": f"no result (rc={driver.proc.returncode}): {driver.stderr_tail()}"}
    res["phase_s"] = time.monotonic() - t0
    res["peer"] = peer_res
    if impl == "mrt" and peer_res and kind == "lat" and (peer_res.get("non_dds") or peer_res.get("transport") != ["DDS"]):
        res["ok"] = False
        res["error"] = f"echo side not on DDS: {peer_res}"
    return res


def start_master(port, env, log_dir):
    out = open(log_dir / "rosmaster.log", "w")
    proc = subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)], env=env, stdout=out,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    uri = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline:
        try:
            code, _, _ = xmlrpc.client.ServerProxy(uri).getSystemState("/bench")
            if code == 1:
                return proc, uri
        except OSError:
            pass
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    stop_proc(proc)
    raise SystemExit(f"rosmaster did not come up on port {port} (see {log_dir}/rosmaster.log)")


def fmt_ratio(x):
    return "   n/a" if x is None else f"{x:6.2f}"


def print_table(results, impls):
    lines = []
    hdr = ("Ratios: micros_rt / raw cyclonedds-py and micros_rt / TCPROS, oriented so that >1 means micros_rt is "
           "SLOWER/WORSE\n(latency: mrt/other; throughput: other/mrt). Target: mrt/dds <= 1.25 everywhere.")
    lines.append(hdr)
    cols = [IMPL_NAMES[i] for i in impls]
    head = f"{'figure':<30}" + "".join(f"{c:>20}" for c in cols) + f"{'mrt/dds':>9}{'mrt/ros':>9}"
    lines.append(head)
    lines.append("-" * len(head))

    def get(impl, key, field):
        r = results.get(impl, {}).get(key)
        if not r or not r.get("ok"):
            return None
        return r.get(field)

    rows = []
    for size, label in ((64, "64 B"), (64 * KiB, "64 KiB")):
        key = f"lat_{size}"
        for field, name in (("median_us", "median"), ("p90_us", "p90"), ("p99_us", "p99")):
            rows.append((f"RTT {label} {name} [us]", key, field, "lower"))
    for size, label in ((64, "64 B"), (MiB, "1 MiB")):
        key = f"tp_{size}"
        rows.append((f"tput {label} [msg/s]", key, "msg_per_s", "higher"))
        rows.append((f"tput {label} [MB/s]", key, "MB_per_s", "higher"))
    worst = []
    for name, key, field, better in rows:
        vals = {i: get(i, key, field) for i in impls}
        cells = "".join(f"{'FAILED' if v is None else f'{v:,.1f}':>20}" for v in vals.values())

        def ratio(other):
            m, o = vals.get("mrt"), vals.get(other)
            if m is None or o is None or m == 0 or o == 0:
                return None
            return m / o if better == "lower" else o / m

        rd, rr = ratio("dds"), ratio("ros")
        if rd is not None:
            worst.append((rd, name))
        lines.append(f"{name:<30}{cells}{fmt_ratio(rd):>9}{fmt_ratio(rr):>9}")
    lines.append("")
    for impl in impls:
        for key, r in sorted(results.get(impl, {}).items()):
            if not r.get("ok"):
                lines.append(f"FAILED {impl} {key}: {r.get('error')}")
            elif r.get("lost") or r.get("lost_in_window"):
                lines.append(f"note {impl} {key}: lost={r.get('lost') or 0} lost_in_window={r.get('lost_in_window') or 0}")
    if worst:
        w = max(worst)
        miss = [n for r, n in worst if r > 1.25]
        lines.append(f"worst mrt/dds ratio: {w[0]:.2f} ({w[1]}); 1.25x target "
                     + ("MET on every figure" if not miss else f"MISSED on: {', '.join(miss)}"))
    return "\n".join(lines)


def combine_rounds(runs):
    """One result per figure: the median over rounds of each round's figure (all rounds must be ok)."""
    if len(runs) == 1:
        return runs[0]
    out = dict(runs[0])
    out["rounds"] = len(runs)
    if not all(r.get("ok") for r in runs):
        bad = next(r for r in runs if not r.get("ok"))
        return dict(bad, rounds=len(runs))
    for field in ("median_us", "p90_us", "p99_us", "msg_per_s", "MB_per_s"):
        if field in runs[0]:
            out[field] = statistics.median(r[field] for r in runs)
    for field in ("lost", "lost_in_window"):
        if field in runs[0]:
            out[field] = sum(r.get(field) or 0 for r in runs)
    return out


def parent_main(args):
    cfg = {"lat_count_small": 2000, "lat_count_large": 500, "tp_warmup": 1.0, "tp_window": 4.0,
           "depth_small": 1000, "depth_large": 32}
    if args.quick:
        cfg.update(lat_count_small=300, lat_count_large=100, tp_warmup=0.5, tp_window=1.5)
    impls = [i.strip() for i in args.impls.split(",") if i.strip()]
    for i in impls:
        if i not in IMPLS:
            raise SystemExit(f"unknown implementation {i!r} (choose from {IMPLS})")
    kinds = [k.strip() for k in args.phases.split(",")]
    log_dir = Path(tempfile.mkdtemp(prefix="micros_rt_bench_"))
    port = free_port()
    domain = random.randint(100, 200)
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "ROS_HOSTNAME", "ROS_NAMESPACE")}
    env.update({
        "ROS_MASTER_URI": f"http://127.0.0.1:{port}/",
        "ROS_IP": "127.0.0.1",
        "ROS_DOMAIN_ID": str(domain),
        "CYCLONEDDS_URI": CYCLONE_XML.as_uri(),
        "ROS_HOME": str(log_dir / "ros_home"),
        "ROS_LOG_DIR": str(log_dir / "ros_log"),
        "PYTHONUNBUFFERED": "1",
    })
    profile_dir = None
    if args.profile_dir:
        Path(args.profile_dir).mkdir(parents=True, exist_ok=True)
        profile_dir = (args.profile_dir, set(args.profile_impls.split(",")))
    print(f"micros_rt benchmark ({'quick' if args.quick else 'full'}): master port {port}, ROS_DOMAIN_ID {domain}, "
          f"CYCLONEDDS_URI {env['CYCLONEDDS_URI']}, logs {log_dir}", flush=True)
    tx0 = eth0_tx()
    results = {i: {} for i in impls}
    master, _uri = start_master(port, env, log_dir)
    t_start = time.monotonic()
    try:
        phases = []
        if "lat" in kinds:
            phases += [("lat", 64), ("lat", 64 * KiB)]
        if "tp" in kinds:
            phases += [("tp", 64), ("tp", MiB)]
        rounds: dict = {i: {} for i in impls}
        for rnd in range(args.rounds):
            # rotate the order each round: this VM's speed drifts, and a fixed order would
            # hand the same implementation the same slot every time
            order = impls[rnd % len(impls):] + impls[:rnd % len(impls)]
            if args.rounds > 1:
                print(f"round {rnd + 1}/{args.rounds} (order {', '.join(order)})", flush=True)
            for kind, size in phases:
                for impl in order:
                    res = run_phase(impl, kind, size, cfg, env, log_dir, profile_dir)
                    rounds[impl].setdefault(f"{kind}_{size}", []).append(res)
                    if not res.get("ok"):
                        summary = f"FAILED: {res.get('error')}"
                    elif kind == "lat":
                        summary = (f"median {res['median_us']:.1f} us  p90 {res['p90_us']:.1f}  p99 {res['p99_us']:.1f}"
                                   f"  (n={res['n']}, transport {res.get('transport')})")
                    else:
                        summary = (f"{res['msg_per_s']:,.0f} msg/s  {res['MB_per_s']:.1f} MB/s  "
                                   f"(lost {res['lost_in_window']}, transport {res.get('transport')})")
                    print(f"  {kind} {size:>8} B  {IMPL_NAMES[impl]:<18} {summary}  [{res['phase_s']:.1f}s]", flush=True)
        for impl in impls:
            for key, runs in rounds[impl].items():
                results[impl][key] = combine_rounds(runs)
    finally:
        stop_proc(master)
    tx1 = eth0_tx()
    delta = None if tx0 is None or tx1 is None else tx1 - tx0
    print()
    print(print_table(results, impls))
    print(f"eth0 tx_packets delta during the run: {delta} (before {tx0}, after {tx1}); "
          f"total {time.monotonic() - t_start:.0f} s")
    if args.json:
        doc = {"mode": "quick" if args.quick else "full", "config": cfg, "domain_id": domain, "master_port": port,
               "eth0_tx_delta": delta, "results": results, "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
        Path(args.json).write_text(json.dumps(doc, indent=2))
        print(f"results saved to {args.json}")
    ok = all(r.get("ok") for d in results.values() for r in d.values())
    return 0 if ok else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="short run (fewer round trips, shorter windows)")
    ap.add_argument("--json", metavar="FILE", help="save the results as JSON")
    ap.add_argument("--impls", default="mrt,dds,ros", help="comma list of mrt,dds,ros (default all)")
    ap.add_argument("--phases", default="lat,tp", help="comma list of lat,tp (default both)")
    ap.add_argument("--rounds", type=int, default=3,
                    help="repeat every phase this many times, rotating the implementations' order; "
                         "each figure is the median over rounds (default 3)")
    ap.add_argument("--profile-dir", help="run the children under cProfile, dumping .prof files here")
    ap.add_argument("--profile-impls", default="mrt", help="which implementations to profile (default mrt)")
    # child-only options
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--impl", help=argparse.SUPPRESS)
    ap.add_argument("--role", help=argparse.SUPPRESS)
    ap.add_argument("--topic", help=argparse.SUPPRESS)
    ap.add_argument("--size", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--depth", type=int, default=1000, help=argparse.SUPPRESS)
    ap.add_argument("--count", type=int, default=1000, help=argparse.SUPPRESS)
    ap.add_argument("--warmup", type=int, default=100, help=argparse.SUPPRESS)
    ap.add_argument("--warmup-s", type=float, default=1.0, help=argparse.SUPPRESS)
    ap.add_argument("--window-s", type=float, default=3.0, help=argparse.SUPPRESS)
    ap.add_argument("--timeout", type=float, default=60.0, help=argparse.SUPPRESS)
    ap.add_argument("--profile", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child_main(args)
    else:
        sys.exit(parent_main(args))


if __name__ == "__main__":
    main()
