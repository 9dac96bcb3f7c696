#!/usr/bin/env python3
"""micros_rt benchmark suite: every transport in the same run, separate processes, loopback only.

    .venv/bin/python benchmarks/run.py            # full run: 3 rounds (transport order rotated per round)
    .venv/bin/python benchmarks/run.py --quick    # 1 round, small counts: a smoke check
    .venv/bin/python benchmarks/run.py --only micros_rt_dds,rospy_tcpros --figures lat64,thr64

Transports (each endpoint its own process; see CONFIG for the configuration of each figure):
  micros_rt_shm     micros_rt's default between two micros_rt nodes of one host: shared memory (iceoryx2), ROS 2
                    visibility auto (no ROS 2 node on the benchmark's domain: one DDS participant, the watcher's)
  micros_rt_shm_ros2   the same with ROS 2 visibility on (MICROS_RT_ROS2=on): a participant per node, what auto
                    becomes once a ROS 2 node is on the domain
  micros_rt_shm_rclpy  the same (auto), and an idle rclpy node joins the scale graph's DDS domain once the graph
                    runs and leaves after the measurement (scale figure only: the switch both ways is measured too)
  micros_rt_shm_local  the same with ROS 2 visibility off (MICROS_RT_ROS2=off): DDS only where a peer needs it
  micros_rt_dds     micros_rt NodeHandle, DDS link (.venv/bin/python, micros_rt's own loopback Cyclone config)
  micros_rt_dds_budget  micros_rt DDS with latency_budget=1 ms on the publisher (write batching), throughput only
  micros_rt_tcpros  micros_rt, the subscriber asks TransportHints().tcp() (TCPROS fallback)
  rospy_tcpros      stock rospy under /usr/bin/python3 (no micros_rt)
  cyclonedds_python raw cyclonedds-python, struct {sequence<octet>}, pre-serialised ddspy_write / batched ddspy_take
  rclpy_fastdds     ROS 2 Jazzy rclpy, Fast DDS, loopback UDP + SHM profile (.venv-ros2/bin/python)

Writes benchmarks/results/latest.json, latest.md and PNG plots; prints a table with ratios vs rospy_tcpros
and the issue's targets. The driver starts its own rosmaster on a free port and kills every child at exit
(also on Ctrl-C). Per-phase logs go to a temporary directory (kept with --keep-logs).
"""

import argparse
import json
import os
import platform
import random
import select
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
PEER = str(HERE / "peer.py")
RESULTS = HERE / "results"
PY = {
    "micros_rt_shm": str(REPO / ".venv/bin/python"),
    "micros_rt_shm_ros2": str(REPO / ".venv/bin/python"),
    "micros_rt_shm_service": str(REPO / ".venv/bin/python"),
    "rospy_tcpros_service": "/usr/bin/python3",
    "micros_rt_shm_rclpy": str(REPO / ".venv/bin/python"),
    "micros_rt_shm_local": str(REPO / ".venv/bin/python"),
    "micros_rt_dds": str(REPO / ".venv/bin/python"),
    "micros_rt_dds_budget": str(REPO / ".venv/bin/python"),
    "micros_rt_tcpros": str(REPO / ".venv/bin/python"),
    "rospy_tcpros": "/usr/bin/python3",
    "cyclonedds_python": str(REPO / ".venv/bin/python"),
    "rclpy_fastdds": str(REPO / ".venv-ros2/bin/python"),
}
IMPL = {"micros_rt_shm": "mrt_shm", "micros_rt_shm_ros2": "mrt_shm", "micros_rt_shm_rclpy": "mrt_shm", "micros_rt_shm_service": "mrt_shm",
        "rospy_tcpros_service": "rospy", "micros_rt_shm_local": "mrt_shm", "micros_rt_dds": "mrt_dds", "micros_rt_dds_budget": "mrt_budget", "micros_rt_tcpros": "mrt_tcpros", "rospy_tcpros": "rospy",
        "cyclonedds_python": "cyclone", "rclpy_fastdds": "rclpy"}
TRANSPORTS = tuple(PY)
BASE = "rospy_tcpros"
CYCLONE_XML = HERE / "cyclonedds_loopback.xml"
FASTDDS_XML = HERE / "fastdds_loopback.xml"
CONFIG = {
    "micros_rt_shm": "advertise(queue_size=None) / subscribe(queue_size=None), default QoS and TransportHints: "
                     "shared memory (SHM, iceoryx2), chosen first between micros_rt nodes of one host and user; "
                     "ROS 2 visibility auto (the default): no ROS 2 node on the domain, one DDS participant (the "
                     "host watcher's)",
    "micros_rt_shm_ros2": "as micros_rt_shm, with MICROS_RT_ROS2=on: every node a DDS participant with a writer and "
                          "reader per topic from its start (what auto becomes once a ROS 2 node is on the domain)",
    "micros_rt_shm_service": "as micros_rt_shm (the defaults), and node 0 of the scale graph offers a std_srvs/Trigger "
                             "(advertise_service: served to ROS 1 and, through the ROS 2 helper, to ROS 2)",
    "micros_rt_shm_rclpy": "as micros_rt_shm (the defaults), and once the scale graph runs an idle rclpy node (a "
                           "subscription of a topic nobody publishes) joins its DDS domain; CPU and PSS are measured "
                           "with it there, then it leaves",
    "rospy_tcpros_service": "as rospy_tcpros, and node 0 of the scale graph offers a std_srvs/Trigger (rospy.Service)",
    "micros_rt_shm_local": "as micros_rt_shm, with MICROS_RT_ROS2=off: no DDS participant until a peer on another "
                           "host needs one; the delivery thread waits on the shared-memory links itself",
    "micros_rt_dds": "advertise(queue_size=None) / subscribe(queue_size=None), default QoS (reliable); "
                     "no CYCLONEDDS_URI, ROS_IP=127.0.0.1 (micros_rt's own loopback Cyclone config)",
    "micros_rt_dds_budget": "as micros_rt_dds, with advertise_with_qos(..., latency_budget=0.001): samples share "
                            "datagrams, sent within 0.5 ms (half the budget; micros_rt.transports.dds.batching); throughput figures only",
    "micros_rt_tcpros": "advertise(queue_size=None); subscribe(queue_size=None, TransportHints().tcp())",
    "rospy_tcpros": "Publisher(queue_size=None) (synchronous), Subscriber(queue_size=None, tcp_nodelay=True)",
    "cyclonedds_python": "reliable (max_blocking 10 s), KEEP_ALL; struct {sequence<octet> data} written "
                         "pre-serialised with ddspy_write, taken 256 at a time with ddspy_take (bytes path); "
                         "CYCLONEDDS_URI=benchmarks/cyclonedds_loopback.xml (lo only, unicast discovery, 63 KB fragments)",
    "rclpy_fastdds": "QoS reliable KEEP_ALL; Fast DDS default publish mode (a publish refused on a full history is retried: back-pressure); benchmarks/fastdds_loopback.xml "
                     "(UDP 127.0.0.1 + SHM), ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; single-threaded spin_once",
}
REALISTIC = {  # kind: (label, size in bytes)
    "image_vga": ("sensor_msgs/Image 640x480 rgb8", 640 * 480 * 3),
    "image_hd": ("sensor_msgs/Image 1920x1080 rgb8", 1920 * 1080 * 3),
    "cloud": ("sensor_msgs/PointCloud2 65,536 pts (1 MiB)", 65536 * 16),
    "scan": ("sensor_msgs/LaserScan 1,081 ranges", 1081 * 8),
    # the same message in ROS 1's documented numpy configuration, both ends (rclpy: its own array.array)
    "scan_np": ("sensor_msgs/LaserScan 1,081 ranges, rospy.numpy_msg", 1081 * 8),
}
#: latest.json sections written by other benchmark scripts (constrained_link.py, cross_host.py), kept when this
#: one rewrites the file
OTHER_SECTIONS = ("constrained_link", "cross_host")
FIGURE_GROUPS = ("lat64", "lat64k", "thr64", "thr1m", "fanout4", "disc", "realistic", "scale")
# (figure, target ratio vs rospy, "<=" or ">=", extra condition)
#: Targets of micros_rt's default on one host (SHM between micros_rt nodes; issue 34), as ratios to rospy in the
#: same run; the ratio column is the headline stack's (:func:`headline`).
TARGETS = {
    "lat64_p50_us": (0.5, "<="), "lat64_p99_us": (1.0, "<="),
    "lat64k_p50_us": (0.4, "<="), "lat64k_p99_us": (1.0, "<="),
    "thr64_msgs_per_s": (1.5, ">="), "thr1m_MB_per_s": (3.0, ">="),
    "fanout4_msgs_per_s": (2.0, ">="), "fanout4_pub_cpu_us_per_msg": (0.7, "<="),
    "disc_ms": (1.0, "<="), "idle_rss_MB": (1.3, "<="),
}
for _k in REALISTIC:
    TARGETS[f"{_k}_p50_us"] = (1.0, "<=")
    TARGETS[f"{_k}_p99_us"] = (1.0, "<=")
    TARGETS[f"{_k}_msgs_per_s"] = (1.0, ">=")
TARGETS.update({"scan_p50_us": (0.7, "<="), "image_vga_p50_us": (0.5, "<="), "image_hd_p50_us": (0.25, "<="),
                "scan_np_msgs_per_s": (1.5, ">=")})
LOWER_BETTER = lambda f: not (f.endswith("per_s"))  # noqa: E731

PROFILES = {
    "full": dict(rounds=3, lat_n=2000, lat_warm=200, latk_n=1000, thr64_n=60000, thr1m_n=600, thr_s=2.0, lat_s=2.5,
                 fan_n=30000, real_lat_n=200, real_s=1.0, scale_ns=(2, 10, 30, 60), scale_steady=3.0, idle_s=2.0,
                 rclpy_lat_n=1000),
    "quick": dict(rounds=1, lat_n=500, lat_warm=50, latk_n=200, thr64_n=10000, thr1m_n=100, thr_s=1.5, lat_s=1.5,
                  fan_n=5000, real_lat_n=50, real_s=1.0, scale_ns=(10,), scale_steady=2.0, idle_s=1.0,
                  rclpy_lat_n=300),
}

CHILDREN = []


# =========================================================================== processes

class Proc:
    def __init__(self, transport, role, args, env, logdir, tag):
        self.tag = tag
        self.out_path = logdir / f"{tag}.out"
        self.err = open(logdir / f"{tag}.err", "w")
        self.t_spawn = time.time()
        self.p = subprocess.Popen([PY[transport], PEER, IMPL[transport], role, *map(str, args)], env=env,
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.err,
                                  text=True, bufsize=1, start_new_session=True)
        CHILDREN.append(self)
        self.lines = []
        self._buf = ""
        self._out = open(self.out_path, "w")

    def poll_lines(self, timeout):
        """Read whatever stdout has (waiting up to ``timeout``)."""
        fd = self.p.stdout.fileno()
        r, _, _ = select.select([fd], [], [], timeout)
        if r:
            chunk = os.read(fd, 1 << 16).decode(errors="replace")
            if not chunk:
                return False
            self._out.write(chunk)
            self._buf += chunk
            while "\n" in self._buf:
                line, self._buf = self._buf.split("\n", 1)
                try:
                    self.lines.append(json.loads(line))
                except ValueError:
                    pass
        return True

    def wait_ev(self, ev, timeout):
        deadline = time.monotonic() + timeout
        while True:
            for d in self.lines:
                if d.get("ev") == ev:
                    return d
                if d.get("ev") == "error":
                    raise PhaseError(f"{self.tag}: {d.get('error')}")
            rem = deadline - time.monotonic()
            if rem <= 0:
                raise PhaseError(f"{self.tag}: no '{ev}' within {timeout:.0f} s")
            if not self.poll_lines(min(rem, 0.2)) and self.p.poll() is not None:
                for d in self.lines:
                    if d.get("ev") == ev:
                        return d
                raise PhaseError(f"{self.tag}: exited ({self.p.returncode}) before '{ev}'; "
                                 f"stderr: {self.stderr_tail()}")

    def wait_ev_i(self, ev, i, timeout):
        """The ``ev`` line whose "i" is ``i`` (multi-spec roles)."""
        deadline = time.monotonic() + timeout
        while True:
            for d in self.lines:
                if d.get("ev") == ev and d.get("i") == i:
                    return d
                if d.get("ev") == "error":
                    raise PhaseError(f"{self.tag}: {d.get('error')}")
            rem = deadline - time.monotonic()
            if rem <= 0:
                raise PhaseError(f"{self.tag}: no '{ev}' #{i} within {timeout:.0f} s")
            if not self.poll_lines(min(rem, 0.2)) and self.p.poll() is not None:
                raise PhaseError(f"{self.tag}: exited ({self.p.returncode}) before '{ev}' #{i}; "
                                 f"stderr: {self.stderr_tail()}")

    def send(self, line):
        try:
            self.p.stdin.write(line + "\n")
            self.p.stdin.flush()
        except (BrokenPipeError, OSError, ValueError):
            pass

    def stderr_tail(self):
        try:
            return " | ".join(Path(self.err.name).read_text().strip().splitlines()[-3:])
        except OSError:
            return ""

    def stop(self, grace=2.0):
        try:
            self.p.stdin.close()
        except (OSError, ValueError):
            pass
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if self.p.poll() is not None:
                break
            try:
                os.killpg(self.p.pid, sig)
            except (ProcessLookupError, PermissionError):
                break
            try:
                self.p.wait(grace)
            except subprocess.TimeoutExpired:
                continue
        while self.poll_lines(0):
            if self.p.stdout.closed:
                break
            if not select.select([self.p.stdout.fileno()], [], [], 0)[0]:
                break
        self._out.close()
        self.err.close()
        if self in CHILDREN:
            CHILDREN.remove(self)


def _pct(s, p):
    return s[min(len(s) - 1, int(round(p / 100 * (len(s) - 1))))]


class PhaseError(Exception):
    pass


def kill_all():
    for c in list(CHILDREN):
        try:
            c.stop(grace=1.0)
        except Exception:
            pass


def eth0_tx():
    """Packets sent on eth0 (the machine is shared: other users' traffic counts too; informational)."""
    try:
        return int(Path("/sys/class/net/eth0/statistics/tx_packets").read_text())
    except (OSError, ValueError):
        return None


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_master(logdir):
    port = free_port()
    env = dict(os.environ, ROS_IP="127.0.0.1", ROS_MASTER_URI=f"http://127.0.0.1:{port}")
    err = open(logdir / "rosmaster.log", "w")
    p = subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)], env=env, stdout=err, stderr=err,
                         stdin=subprocess.DEVNULL, start_new_session=True)
    uri = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            xmlrpc.client.ServerProxy(uri).getSystemState("/bench")
            return p, uri
        except OSError:
            time.sleep(0.1)
    p.kill()
    raise SystemExit("rosmaster did not come up within 20 s")


def child_env(transport, master_uri, domain):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "CYCLONEDDS", "FASTRTPS", "FASTDDS", "RMW_", "PYTHONPATH", "AMENT",
                                "MICROS_RT"))}
    env.update(ROS_MASTER_URI=master_uri, ROS_IP="127.0.0.1", ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1",
               ROS_HOME=str(Path(tempfile.gettempdir()) / "micros_rt_bench_roshome"))
    if transport.startswith("micros_rt_"):
        env["PYTHONPATH"] = str(REPO)  # this checkout's micros_rt, whichever one the venv installed (editable)
    if transport.startswith("micros_rt_") and not transport.startswith("micros_rt_shm"):
        env["MICROS_RT_DISABLE_SHM"] = "1"  # these measure the DDS plane (and TCPROS) between local processes
    if transport == "micros_rt_shm_local":
        env["MICROS_RT_ROS2"] = "off"
    if transport == "micros_rt_shm_ros2":
        env["MICROS_RT_ROS2"] = "on"
    if transport in ("cyclonedds_python", "rclpy_fastdds"):
        # a domain of their own: a DDS participant that is not micros_rt's (or its discovery data, until its
        # lease ends) would make micros_rt's auto visibility turn on in the phases after it
        env["ROS_DOMAIN_ID"] = str(domain + 1)
    if transport == "cyclonedds_python":
        env["CYCLONEDDS_URI"] = f"file://{CYCLONE_XML}"
    if transport == "rclpy_fastdds":
        env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", FASTRTPS_DEFAULT_PROFILES_FILE=str(FASTDDS_XML))
    return env


# =========================================================================== /proc helpers

def cpu_ticks(pid):
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return int(f[11]) + int(f[12])
    except (OSError, IndexError):
        return 0


def with_children(pids):
    """``pids`` and their child processes (a micros_rt node's ROS 2 services helper is one): what they cost too."""
    out = list(pids)
    for pid in pids:
        try:
            for task in Path(f"/proc/{pid}/task").iterdir():
                out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
    return out


def rss_mb(pid):
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def pss_mb(pid):
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


# =========================================================================== phases

class Bench:
    def __init__(self, args, prof, logdir):
        self.a, self.P, self.logdir = args, prof, logdir
        self.master, self.master_uri = start_master(logdir)
        self.domain = random.randrange(100, 200)
        self.n = 0
        self.samples = {}  # (transport, figure) -> list of latency samples (last round)
        self.errors = []
        self.t0 = time.monotonic()
        self.prefix = ""

    def progress(self, what):
        el = time.monotonic() - self.t0
        sys.stderr.write(f"\r\033[K{self.prefix} {what} ({el:.0f} s)")
        sys.stderr.flush()

    def env(self, t):
        return child_env(t, self.master_uri, self.domain)

    def spawn(self, t, role, args, tag):
        self.n += 1
        return Proc(t, role, args, self.env(t), self.logdir, f"{self.n:03d}_{t}_{role}_{tag}")

    def topic(self, name):
        return f"/bench_{name}_{random.randrange(1 << 30)}"

    def lat(self, t, specs):
        """specs: [(tag, kind, size, count, warmup)]: one echo and one ping process, one topic pair each."""
        if t == "rclpy_fastdds":
            specs = [(tag, k, sz, min(c, self.P["rclpy_lat_n"]), w) for tag, k, sz, c, w in specs]
        topic = self.topic("lat")
        sp = ",".join(f"{k}:{sz}:{c}:{w}" for _, k, sz, c, w in specs)
        common = ["--topic", topic, "--specs", sp, "--seconds", self.P["lat_s"],
                  "--timeout", 60 + len(specs) * (self.P["lat_s"] + 5)]
        echo = self.spawn(t, "echo", common, "lat")
        out = {}
        try:
            echo.wait_ev("ready", 30)
            ping = self.spawn(t, "ping", common, "lat")
            try:
                for i, (tag, _, _, count, _) in enumerate(specs):
                    self.progress(tag)
                    r = ping.wait_ev_i("result", i, 40 + self.P["lat_s"] + 5)
                    rt = sorted(r["rtts"])
                    if not rt:
                        raise PhaseError(f"{tag}: no round trips ({r['lost']} lost)")
                    self.samples[(t, tag)] = rt
                    out.update({f"{tag}_p50_us": statistics.median(rt), f"{tag}_p99_us": _pct(rt, 99),
                                f"{tag}_rt_lost": r["lost"]})
            finally:
                ping.stop()
        finally:
            echo.stop()
        return out

    def thr(self, t, specs, subs=1, seconds=None):
        """specs: [(tag, kind, size, count)]: one sender and ``subs`` receivers, one topic per spec, in turn;
        each spec sends ``count`` messages or for its time bound (``seconds`` for bytes, ``real_s`` for the
        realistic types, whose count is a placeholder), whichever comes first."""
        seconds = seconds or self.P["thr_s"]
        topic = self.topic("thr")
        sp = ",".join(f"{k}:{sz}:{c}:0:{seconds if k == 'bytes' else self.P['real_s']}" for _, k, sz, c in specs)
        limit = 60 + len(specs) * (max(seconds, self.P["real_s"]) + 10)
        common = ["--topic", topic, "--specs", sp, "--timeout", limit]
        recvs, send, out = [], None, {}
        try:
            for j in range(subs):
                recvs.append(self.spawn(t, "recv", [*common, "--drain", 2.0], f"thr{j}"))
            for r in recvs:
                r.wait_ev("ready", 30)
            send = self.spawn(t, "send", [*common, "--seconds", seconds, "--subs", subs], "thr")
            for i, (tag, _, size, _) in enumerate(specs):
                self.progress(tag)
                s = send.wait_ev_i("sent", i, 40 + seconds)
                for r in recvs:
                    r.send(f"SENT {i} {s['sent']}")
                res = [r.wait_ev_i("result", i, 30) for r in recvs]
                send.send(f"NEXT {i}")
                sent = s["sent"]
                got = [r["received"] for r in res]
                rates = [(g - 1) / r["span_s"] if r["span_s"] else 0.0 for g, r in zip(got, res)]
                agg = sum(rates)
                out.update({f"{tag}_msgs_per_s": agg, f"{tag}_MB_per_s": agg * size / 1e6,
                            f"{tag}_lost": sum(sent - g for g in got), f"{tag}_sent": sent * subs})
                if subs > 1:
                    out[f"{tag}_pub_cpu_us_per_msg"] = s["cpu_s"] * 1e6 / max(1, sum(got))
        finally:
            if send is not None:
                send.stop()
            for r in recvs:
                r.stop()
        return out

    def disc(self, t):
        topic = self.topic("disc")
        common = ["--topic", topic, "--kind", "bytes", "--size", 64, "--timeout", 60]
        lis = self.spawn(t, "listener", common, "disc")
        talk = None
        try:
            lis.wait_ev("ready", 30)
            time.sleep(0.3)
            talk = self.spawn(t, "talker", common, "disc")
            f = lis.wait_ev("first", 40)
            if f.get("t") is None:
                raise PhaseError("listener never heard the talker")
            disc_ms = (f["t"] - talk.t_spawn) * 1e3
            talk.send("IDLE")
            talk.wait_ev("idle", 10)
            time.sleep(self.P["idle_s"])
            rss = rss_mb(talk.p.pid)
        finally:
            if talk is not None:
                talk.stop()
            lis.stop()
        return {"disc_ms": disc_ms, "idle_rss_MB": rss}

    def scale(self, t, n):
        topic = self.topic(f"g{n}")
        procs = []
        t0 = time.time()
        try:
            for i in range(n):
                procs.append(self.spawn(t, "graph", ["--topic", topic, "--nodes", n, "--index", i,
                                                     "--kind", "bytes", "--size", 64, "--timeout", 180,
                                                     *(["--service"] if t.endswith("_service") else [])], f"n{n}"))
            last = 0.0
            for p in procs:
                last = max(last, p.wait_ev("connected", max(5.0, 30 + 2 * n - (time.time() - t0)))["t"])
            connect_s = last - t0
            pids = with_children([p.p.pid for p in procs]) + (
                [self.master.pid] if t.startswith(("micros", "rospy")) else [])
            switch = {}
            if t == "micros_rt_shm_rclpy":
                ros2 = self.ros2_joins(procs, pids, n)
                switch = ros2.result
            time.sleep(1.0)
            c0, w0 = sum(cpu_ticks(x) for x in pids), time.monotonic()
            time.sleep(self.P["scale_steady"])
            c1, w1 = sum(cpu_ticks(x) for x in pids), time.monotonic()
            cpu_pct = (c1 - c0) / os.sysconf("SC_CLK_TCK") / (w1 - w0) * 100
            pss = [pss_mb(p.p.pid) for p in procs]
            pss = statistics.fmean([x for x in pss if x is not None])
            if t == "micros_rt_shm_rclpy":
                switch.update(ros2.leave())
            else:  # the same count without a ROS 2 node, for comparison: what the graph lost since it connected
                for p in procs:
                    p.send("STATS")
                stats = [p.wait_ev("stats", 30) for p in procs]
                switch[f"scale{n}_lost"] = sum(s["lost"] for s in stats)
        finally:
            if t == "micros_rt_shm_rclpy" and "ros2" in locals():
                ros2.stop()
            for p in procs:
                p.stop(grace=1.0)
        return {f"scale{n}_connect_s": connect_s, f"scale{n}_cpu_pct": cpu_pct, f"scale{n}_pss_MB": pss, **switch}

    def ros2_joins(self, procs, pids, n):
        """An idle rclpy node joins the scale graph's DDS domain (micros_rt_shm_rclpy): CPU per second from its
        start, until the graph's CPU is back within 20 % of its level before (the switch)."""
        return Ros2Joins(self, procs, pids, n)

    def stop(self):
        kill_all()
        try:
            os.killpg(self.master.pid, signal.SIGTERM)
            self.master.wait(3)
        except (ProcessLookupError, subprocess.TimeoutExpired, PermissionError):
            self.master.kill()


class Ros2Joins:
    """The switch of a scale graph when an idle rclpy node joins its DDS domain and when it leaves: the graph's CPU
    in 1 s windows (the rclpy node's own not counted), how long until it is back within 20 % of the steady level,
    and the messages the graph's nodes lost meanwhile."""

    WINDOWS = 12

    def __init__(self, bench, procs, pids, n):
        self.procs, self.pids, self.n = procs, pids, n
        before = self._windows(3)
        self.base = statistics.median(before)
        env = dict(bench.env("rclpy_fastdds"), ROS_DOMAIN_ID=str(bench.domain))  # the graph's domain, not its own
        bench.n += 1
        self.node = Proc("rclpy_fastdds", "listener", ["--topic", bench.topic("idle"), "--kind", "bytes", "--size", 64,
                                                       "--timeout", 600], env, bench.logdir, f"{bench.n:03d}_rclpy_idle")
        self.node.wait_ev("ready", 60)
        joined = self._windows(self.WINDOWS)
        self.result = {f"scale{n}_join_cpu_pct_per_s": joined, f"scale{n}_before_cpu_pct": self.base,
                       f"scale{n}_join_settled_s": self._settled(joined)}

    def _windows(self, k):
        out = []
        for _ in range(k):
            c0, w0 = sum(cpu_ticks(x) for x in self.pids), time.monotonic()
            time.sleep(1.0)
            c1, w1 = sum(cpu_ticks(x) for x in self.pids), time.monotonic()
            out.append(round((c1 - c0) / os.sysconf("SC_CLK_TCK") / (w1 - w0) * 100, 1))
        return out

    def _settled(self, windows):
        """Seconds until the graph's CPU stays within 20 % (and 3 points) of its level with the node there."""
        level = statistics.median(windows[-4:])
        for i in range(len(windows)):
            if all(abs(w - level) <= max(0.2 * level, 3.0) for w in windows[i:]):
                return i
        return len(windows)

    def leave(self):
        self.stop()
        left = self._windows(self.WINDOWS)
        for p in self.procs:
            p.send("STATS")
        stats = [p.wait_ev("stats", 30) for p in self.procs]
        return {f"scale{self.n}_leave_cpu_pct_per_s": left, f"scale{self.n}_leave_settled_s": self._settled(left),
                f"scale{self.n}_switch_lost": sum(s["lost"] for s in stats),
                f"scale{self.n}_switch_recv": sum(s["recv"] for s in stats)}

    def stop(self):
        if self.node.p.poll() is None:
            self.node.stop(grace=1.0)


#: Figures whose messages are large (over glibc's 128 KiB mmap threshold) each get their own pair of
#: processes. In one process a large message type measured after a larger one ran on memory that one had
#: left: glibc raises its mmap threshold to the largest block freed, so later large buffers no longer cost
#: page faults. Stock rospy's PointCloud2 round trip measured 605-677 us after the 6 MB Image, 1,697 us after
#: the 0.9 MB one and 1,971-2,193 us first or alone (micros_rt, which sets glibc's thresholds itself, 950-1,267
#: us in any order); rospy's 1 MiB throughput, the first large type of its process, ran cold for the others.
LARGE_FIGURES = ("thr1m", "image_vga", "image_hd", "cloud")


def fresh_process_groups(tags):
    """[[tag, ...], ...]: the small figures together, each large one alone (see LARGE_FIGURES)."""
    small = [x for x in tags if x not in LARGE_FIGURES]
    return ([small] if small else []) + [[x] for x in tags if x in LARGE_FIGURES]


def plan(args, P):
    """[(round, transport, label, spec)]: per transport and round one latency phase (64 B, 64 KiB, realistic
    types), one throughput phase (the same), fan-out, discovery; the scale graph in round 1 only."""
    steps = []
    ts = list(args.only)
    g = set(args.figures)
    for rnd in range(P["rounds"]):
        order = ts[rnd % len(ts):] + ts[:rnd % len(ts)]
        for t in order:
            real = "realistic" in g and t != "cyclonedds_python"  # raw DDS: no ROS message types here
            lat = [x for x in ("lat64", "lat64k") if x in g] + (list(REALISTIC) if real else [])
            if t == "micros_rt_dds_budget":  # a throughput configuration: batching trades latency for rate
                lat = []
            thr = [x for x in ("thr64", "thr1m") if x in g] + (list(REALISTIC) if real else [])
            for kind, label, tags in (("lat", "latency", lat), ("thr", "throughput", thr)):
                for group in fresh_process_groups(tags):
                    steps.append((rnd, t, label, (kind, group)))
            if "fanout4" in g:
                steps.append((rnd, t, "fanout4", ("fanout4",)))
            if "disc" in g and t != "micros_rt_dds_budget":
                steps.append((rnd, t, "disc", ("disc",)))
            if "scale" in g and rnd == 0 and t != "micros_rt_dds_budget":
                for n in P["scale_ns"]:
                    steps.append((rnd, t, f"scale N={n}", ("scale", n)))
    return steps


def run_step(b, P, t, spec):
    kind = spec[0]
    if kind == "lat":
        specs = []
        for tag in spec[1]:
            if tag == "lat64":
                specs.append(("lat64", "bytes", 64, P["lat_n"], P["lat_warm"]))
            elif tag == "lat64k":
                specs.append(("lat64k", "bytes", 65536, P["latk_n"], P["lat_warm"] // 2))
            else:
                specs.append((tag, tag, REALISTIC[tag][1], P["real_lat_n"], 10))
        return b.lat(t, specs)
    if kind == "thr":
        specs = []
        for tag in spec[1]:
            if tag == "thr64":
                specs.append(("thr64", "bytes", 64, P["thr64_n"]))
            elif tag == "thr1m":
                specs.append(("thr1m", "bytes", 1 << 20, P["thr1m_n"]))
            else:
                # a sustained rate: real_s seconds of sending (the time bound of the spec), not a count. 300
                # LaserScans took 15 ms and 2,776 (24 MB) 30-90 ms: the figure was the stream's start-up
                # (discovery's last steps, the writers' first acknowledgements), not a rate
                specs.append((tag, tag, REALISTIC[tag][1], 10 ** 7))
        return b.thr(t, specs)
    if kind == "fanout4":
        return b.thr(t, [("fanout4", "bytes", 64, P["fan_n"])], subs=4)
    if kind == "disc":
        return b.disc(t)
    if kind == "scale":
        return b.scale(t, spec[1])
    raise ValueError(spec)


# =========================================================================== reporting

def machine():
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        cyc = subprocess.run([PY["micros_rt_dds"], "-c", "import importlib.metadata as m;"
                              "print(m.version('cyclonedds'))"], capture_output=True, text=True,
                             timeout=20).stdout.strip()
    except Exception:
        cyc = "?"
    try:
        rcl = subprocess.run([PY["rclpy_fastdds"], "-c", "import importlib.metadata as m;"
                              "print(m.version('rclpy'))"], capture_output=True, text=True,
                             timeout=20).stdout.strip() or "?"
    except Exception:
        rcl = "?"
    return {"cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(), "os": _os_name(),
            "python": platform.python_version(), "cyclonedds": cyc, "rclpy": rcl,
            "mem_GB": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9, 1)}


def _os_name():
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                return line.split("=", 1)[1].strip('"')
    except OSError:
        pass
    return platform.system()


def fmt(v):
    if v is None:
        return "—"
    if isinstance(v, int) or (isinstance(v, float) and v.is_integer() and abs(v) < 1e6 and abs(v) >= 100):
        return f"{int(v):,}"
    if abs(v) >= 100:
        return f"{v:,.0f}"
    if abs(v) >= 10:
        return f"{v:.1f}"
    return f"{v:.2f}"


def headline(transports):
    """The micros_rt stack the ratio column and the targets are about: its default between two micros_rt nodes of
    one host (SHM) when measured, else DDS."""
    return "micros_rt_shm" if "micros_rt_shm" in transports else "micros_rt_dds"


def verdict(fig, figs, t):
    """'ok'/'MISS' for a micros_rt stack vs rospy, '' otherwise."""
    if t not in ("micros_rt_shm", "micros_rt_shm_ros2", "micros_rt_shm_local", "micros_rt_dds", "micros_rt_dds_budget") or fig not in TARGETS:
        return ""
    v, b = figs.get(t, {}).get(fig), figs.get(BASE, {}).get(fig)
    if v is None or not b:
        return ""
    lim, op = TARGETS[fig]
    r = v / b
    ok = r <= lim if op == "<=" else r >= lim
    if fig.startswith(("thr", "fanout")) or fig.endswith("_msgs_per_s"):
        pre = fig.rsplit("_", 3)[0] if not fig.startswith("fanout") else "fanout4"
        if figs[t].get(f"{pre}_lost"):
            ok = False
    return "ok" if ok else "MISS"


def markdown(data, figs, spread, transports, made, errors, wall):
    """latest.md's lines: the machine, the table and the configurations of a run (also from a saved latest.json:
    ``markdown_from(path)``)."""
    mach = data["machine"]
    md = ["## Performance", "",
          f"Measured with `{data['command']}` ({data['rounds']} round(s), {wall / 60:.1f} min) on "
          f"{mach['cpu']}, {mach['cores']} cores, {mach['mem_GB']} GB, {mach['os']}, Linux {mach['kernel']}, "
          f"Python {mach['python']}, cyclonedds {mach['cyclonedds']}, rclpy {mach['rclpy']}. "
          "Every endpoint is its own process, loopback only; figures are medians over rounds (loss: the worst "
          "round). Latency: ping-pong round trip in µs. Throughput: one-way, measured at the receiver; lost = "
          f"sent − received. The last three columns compare {headline(transports)} (micros_rt's default on one "
          "host when measured) with stock rospy TCPROS measured in the same run, against the targets of "
          "issue 34.", "",
          table(figs, spread, transports, md=True), "",
          "Configurations:", ""]
    md += [f"- **{t}**: {CONFIG.get(t, data['config'].get(t, ''))}" for t in transports]
    if made:
        md += ["", "Plots: " + ", ".join(f"[{m}](benchmarks/results/{m})" for m in made)]
    if errors:
        md += ["", "Phases that failed in this run:", ""] + [f"- {e}" for e in errors]
    return md


def markdown_from(path):
    """Write latest.md beside a saved ``latest.json`` (nothing is measured)."""
    path = Path(path)
    data = json.loads(path.read_text())
    transports = list(data["config"])
    made = sorted(p.name for p in path.parent.glob("*.png") if p.name != "summary.png")
    md = markdown(data, data["figures"], data["spread"], transports, made, data.get("errors", []), data["wall_s"])
    (path.parent / "latest.md").write_text("\n".join(md) + "\n")


def table(figs, spread, transports, md=False):
    names = sorted({f for t in transports for f, v in figs.get(t, {}).items()
                    if not isinstance(v, (dict, list)) and not f.endswith("_sent")}, key=_fig_order)
    short = {"micros_rt_shm": "mrt SHM", "micros_rt_shm_ros2": "mrt SHM ROS2 on", "micros_rt_shm_rclpy": "mrt SHM +rclpy", "micros_rt_shm_local": "mrt SHM local", "micros_rt_dds": "mrt DDS", "micros_rt_dds_budget": "mrt budget", "micros_rt_tcpros": "mrt TCPROS", "rospy_tcpros": "rospy",
             "cyclonedds_python": "cyclone-py", "rclpy_fastdds": "rclpy", "micros_rt_shm_service": "mrt SHM +service",
             "rospy_tcpros_service": "rospy +service"}
    cols = [t for t in transports]
    head = ["figure"] + [short.get(t, t) for t in cols]
    budget = "micros_rt_dds_budget" in cols
    head_t = headline(cols)
    if BASE in cols:
        head += [f"{short.get(head_t, head_t)}/rospy", "target", ""] + (["budget/rospy", ""] if budget else [])
    rows = []
    for f in names:
        row = [f]
        for t in cols:
            v = figs.get(t, {}).get(f)
            s = spread.get(t, {}).get(f)
            cell = fmt(v)
            if s and v is not None and s[0] != s[1] and not md:
                pass
            row.append(cell)
        if BASE in cols:
            v, b = figs.get(head_t, {}).get(f), figs.get(BASE, {}).get(f)
            row.append(f"{v / b:.2f}x" if v is not None and b and not f.endswith("lost") else "")
            tg = TARGETS.get(f)
            row.append(f"{tg[1]} {tg[0]}x" if tg else "")
            row.append(verdict(f, figs, head_t))
            if budget:
                v = figs.get("micros_rt_dds_budget", {}).get(f)
                row.append(f"{v / b:.2f}x" if v is not None and b and not f.endswith("lost") else "")
                row.append(verdict(f, figs, "micros_rt_dds_budget"))
        rows.append(row)
    if md:
        out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        out += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(out)
    w = [max(len(str(r[i])) for r in [head] + rows) for i in range(len(head))]
    lines = ["  ".join(str(c).rjust(w[i]) if i else str(c).ljust(w[i]) for i, c in enumerate(r))
             for r in [head] + rows]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)


def _fig_order(f):
    order = ["lat64_", "lat64k_", "thr64_", "thr1m_", "fanout4_", "disc", "idle", "image_vga", "image_hd",
             "cloud", "scan", "scale2_", "scale10_", "scale30_", "scale60_"]
    for i, p in enumerate(order):
        if f.startswith(p):
            return (i, f)
    return (99, f)


#: one colour per stack in every plot (stock rospy red, micros_rt's DDS blue, SHM orange, its TCPROS grey;
#: cross_host.py and constrained_link.py use the same for the stacks they share)
COLOURS = {"micros_rt_shm": "#ff7f0e", "micros_rt_shm_ros2": "#8c564b", "micros_rt_shm_rclpy": "#bcbd22", "micros_rt_shm_service": "#e377c2",
           "rospy_tcpros_service": "#ff9896", "micros_rt_shm_local": "#ffbb78", "micros_rt_dds": "#1f77b4",
           "micros_rt_dds_budget": "#17becf", "micros_rt_tcpros": "#7f7f7f", "rospy_tcpros": "#d62728",
           "cyclonedds_python": "#2ca02c", "rclpy_fastdds": "#9467bd"}


def targets_of(data):
    """The targets a results file was measured against (``latest.json["targets"]``: "<= 0.8x rospy_tcpros"), as
    :data:`TARGETS` holds them, so a plot redrawn from an older run shows that run's targets, not today's."""
    out = {}
    for fig, text in (data.get("targets") or {}).items():
        op, ratio = text.split()[:2]
        out[fig] = (float(ratio.rstrip("x")), op)
    return out or dict(TARGETS)


def _target_value(figs, targets, fig):
    """(value, words) of the target line for ``fig``: the target ratio times rospy's figure in the same run."""
    tg, base = targets.get(fig), figs.get(BASE, {}).get(fig)
    if not tg or not base:
        return None
    lim, op = tg
    return lim * base, f"target {'≤' if op == '<=' else '≥'} {lim:g}x rospy"


def replot(results_json, outdir=None):
    """Redraw a run's plots from its ``latest.json`` (no benchmark is run): the throughput, realistic-type and
    scale plots. The latency distributions need the run's raw samples, which latest.json does not keep."""
    import json as _json
    path = Path(results_json)
    data = _json.loads(path.read_text())
    figs = data["figures"]
    transports = [t for t in TRANSPORTS if t in figs]
    return plots(figs, {}, transports, Path(outdir) if outdir else path.parent, targets=targets_of(data))


def plots(figs, samples, transports, outdir, targets=None):
    """The run's plots; each title says whether lower or higher is better, and each figure with a target (a ratio
    to stock rospy in the same run, for the headline micros_rt stack) draws it as a dashed black line."""
    targets = TARGETS if targets is None else targets
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import matplotlib.ticker
    except ImportError:
        return ["(matplotlib not installed: no plots; apt-get install python3-matplotlib)"]
    colors = COLOURS
    head = headline(transports)
    made = []
    # latency distributions
    for tag, title in (("lat64", "64 B"), ("lat64k", "64 KiB")):
        ts = [t for t in transports if (t, tag) in samples]
        if not ts:
            continue
        fig, ax = plt.subplots(figsize=(10, 1.2 + 0.75 * len(ts)))
        data = [samples[(t, tag)] for t in ts]
        parts = ax.violinplot(data, vert=False, showextrema=False, quantiles=[[0.5, 0.99]] * len(ts))
        for body, t in zip(parts["bodies"], ts):
            body.set_facecolor(colors[t])
            body.set_alpha(0.65)
        parts["cquantiles"].set_color("black")
        lo = min(min(d) for d in data)
        hi = max(max(d) for d in data)
        ax.set_xlim(lo / 1.3, hi * 1.3)
        from matplotlib.transforms import blended_transform_factory
        tr = blended_transform_factory(ax.transAxes, ax.transData)
        for i, (t, d) in enumerate(zip(ts, data)):
            p50 = figs[t].get(f"{tag}_p50_us")
            p99 = figs[t].get(f"{tag}_p99_us")
            ax.text(1.01, i + 1, f"p50 {fmt(p50)} µs\np99 {fmt(p99)} µs", fontsize=8, ha="left", va="center",
                    transform=tr)
        ax.set_yticks(range(1, len(ts) + 1), ts)
        ax.set_xscale("log")
        from matplotlib.ticker import LogLocator, ScalarFormatter
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        tv = _target_value(figs, targets, f"{tag}_p50_us")
        if tv:
            ax.axvline(tv[0], color="black", linestyle="--", linewidth=1, label=f"{tv[1]}'s p50 ({head}'s p50)")
            ax.set_xlim(min(lo, tv[0]) / 1.3, max(hi, tv[0]) * 1.3)
            ax.legend(fontsize=8, loc="upper left")
        ax.set_xlabel("round trip (µs, log scale); black ticks: p50 and p99 of this round; text: median over rounds")
        ax.set_title(f"Round-trip latency, {title} std_msgs/UInt8MultiArray, loopback, last round (lower is better)")
        ax.grid(axis="x", which="both", alpha=0.3)
        fig.tight_layout()
        p = outdir / f"latency_{tag}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        made.append(p.name)
    # throughput bars
    groups = [("thr64_msgs_per_s", "64 B one-way\n(msg/s, higher is better)", "thr64_lost"),
              ("thr1m_MB_per_s", "1 MiB one-way\n(MB/s, higher is better)", "thr1m_lost"),
              ("fanout4_msgs_per_s", "fan-out 1→4, 64 B\n(aggregate msg/s, higher is better)", "fanout4_lost")]
    groups = [g for g in groups if any(g[0] in figs.get(t, {}) for t in transports)]
    if groups:
        fig, axes = plt.subplots(1, len(groups), figsize=(4.2 * len(groups), 4.2), squeeze=False)
        for ax, (f, title, lostf) in zip(axes[0], groups):
            ts = [t for t in transports if f in figs.get(t, {})]
            vals = [figs[t][f] for t in ts]
            bars = ax.bar(range(len(ts)), vals, color=[colors[t] for t in ts])
            for bar, t in zip(bars, ts):
                lost = figs[t].get(lostf)
                ax.text(bar.get_x() + bar.get_width() / 2, bar.get_height(),
                        f"{fmt(figs[t][f])}\nlost {fmt(lost)}", ha="center", va="bottom", fontsize=7,
                        color="black" if not lost else "red")
            ax.set_xticks(range(len(ts)), [t.replace("_", "\n", 1) for t in ts], fontsize=7)
            ax.set_title(title, fontsize=10)
            top = max(vals + [1])
            tv = _target_value(figs, targets, f)
            if tv:
                ax.axhline(tv[0], color="black", linestyle="--", linewidth=1, label=f"{tv[1]} ({head})")
                ax.legend(fontsize=7, loc="upper right")
                top = max(top, tv[0])
            ax.set_ylim(0, top * 1.25)
            ax.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:,.0f}"))
            ax.grid(axis="y", alpha=0.3)
        fig.suptitle("Throughput, higher is better (median of rounds, measured at the receiver; "
                     "lost = sent − received)")
        fig.tight_layout()
        p = outdir / "throughput.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        made.append(p.name)
    # realistic types
    ks = [k for k in REALISTIC if any(f"{k}_p50_us" in figs.get(t, {}) for t in transports)]
    if ks:
        fig, axes = plt.subplots(2, len(ks), figsize=(3.6 * len(ks), 6.5), squeeze=False)
        for j, k in enumerate(ks):
            ts = [t for t in transports if f"{k}_p50_us" in figs.get(t, {})]
            for i, (f, yl) in enumerate(((f"{k}_p50_us", "round trip p50 (µs)\nlower is better"),
                                         (f"{k}_msgs_per_s", "one-way msg/s\nhigher is better"))):
                ax = axes[i][j]
                vals = [figs[t].get(f) or 0 for t in ts]
                bars = ax.bar(range(len(ts)), vals, color=[colors[t] for t in ts])
                for bar, t, v in zip(bars, ts, vals):
                    extra = ""
                    if i == 1:
                        lost = figs[t].get(f"{k}_lost")
                        extra = f"\nlost {fmt(lost)}"
                    ax.text(bar.get_x() + bar.get_width() / 2, bar.get_height(), fmt(v) + extra,
                            ha="center", va="bottom", fontsize=7)
                ax.set_xticks(range(len(ts)), [t.split("_")[0] + ("\n" + t.split("_", 1)[1] if "_" in t else "")
                                               for t in ts], fontsize=6)
                top = max(vals + [1])
                tv = _target_value(figs, targets, f)
                if tv:
                    ax.axhline(tv[0], color="black", linestyle="--", linewidth=1, label=tv[1])
                    ax.legend(fontsize=6, loc="upper right")
                    top = max(top, tv[0])
                ax.set_ylim(0, top * 1.3)
                ax.set_ylabel(yl, fontsize=8)
                if i == 0:
                    ax.set_title(REALISTIC[k][0], fontsize=9)
                ax.grid(axis="y", alpha=0.3)
        fig.suptitle("Realistic message types: round trip, lower is better (top); rate, higher is better (bottom)"
                     + (f"; dashed: {head}'s target" if any(_target_value(figs, targets, f"{k}_p50_us") for k in ks)
                        else ""))
        fig.tight_layout()
        p = outdir / "realistic.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        made.append(p.name)
    # scale curves
    ns = sorted({int(f[5:].split("_")[0]) for t in transports for f in figs.get(t, {}) if f.startswith("scale")})
    if ns:
        fig, axes = plt.subplots(1, 3, figsize=(13, 4))
        for ax, (suf, yl) in zip(axes, (("connect_s", "start → fully connected (s)"),
                                        ("cpu_pct", "steady CPU, all nodes + master (% of a core)"),
                                        ("pss_MB", "PSS per node (MB)"))):
            for t in transports:
                pts = [(n, figs.get(t, {}).get(f"scale{n}_{suf}")) for n in ns]
                pts = [(n, v) for n, v in pts if v is not None]
                if pts:
                    ax.plot([n for n, _ in pts], [v for _, v in pts], "o-", color=colors[t], label=t)
            ax.set_xlabel("nodes N (each: 1 topic at 10 Hz out, 3 in)")
            ax.set_ylabel(yl, fontsize=9)
            ax.set_xticks(ns)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle("A graph of N nodes on one host (lower is better; no target set)")
        fig.tight_layout()
        p = outdir / "scale.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        made.append(p.name)
    return made


def summary_rows(results=RESULTS):
    """The README's summary: micros_rt against stock rospy in the same run, one row per figure, read from the
    committed results (nothing is measured): (section, words, stack, ratio, target ratio or None, lower is
    better). One host: the SHM run (one_host/); between hosts: cross_host.py at 1 Gbit/s,
    MTU 1500; a 40 Mbit/s link: constrained_link.py (control p99, medians of rounds; targets from issue 19)."""
    import json as _json
    rows = []
    one = _json.loads((Path(results) / "one_host" / "latest.json").read_text())
    figs, tg = one["figures"], targets_of(one)
    shm, base = figs["micros_rt_shm"], figs[BASE]
    for fig, words in (("lat64_p50_us", "round trip 64 B, p50"), ("lat64k_p50_us", "round trip 64 KiB, p50"),
                       ("image_vga_p50_us", "round trip Image 640x480, p50"),
                       ("image_hd_p50_us", "round trip Image 1920x1080, p50"),
                       ("cloud_p50_us", "round trip PointCloud2 1 MiB, p50"),
                       ("scan_p50_us", "round trip LaserScan, p50"), ("disc_ms", "spawn to first message"),
                       ("thr64_msgs_per_s", "one-way 64 B, msg/s"), ("thr1m_MB_per_s", "one-way 1 MiB, MB/s"),
                       ("fanout4_msgs_per_s", "fan-out 1 to 4, msg/s"),
                       ("image_vga_msgs_per_s", "Image 640x480, msg/s")):
        rows.append(("one host", words, "micros_rt_shm", shm[fig] / base[fig], tg.get(fig, (None,))[0],
                     LOWER_BETTER(fig)))
    # the many-node figures: the default (ROS 2 visibility auto, no ROS 2 node), on (a participant per node, what
    # auto becomes with a ROS 2 node on the domain) and off; targets from issue 34
    for stack, words, cpu_target in (("micros_rt_shm", "default", 1.2), ("micros_rt_shm_ros2", "ROS 2 visibility on", 1.2),
                                     ("micros_rt_shm_local", "ROS 2 visibility off", 1.0)):
        if stack not in figs or "scale60_cpu_pct" not in figs[stack]:
            continue
        rows.append(("one host", f"60 nodes, CPU ({words})", stack,
                     figs[stack]["scale60_cpu_pct"] / base["scale60_cpu_pct"], cpu_target, True))
    rows.append(("one host", "60 nodes, connect (default)", "micros_rt_shm",
                 shm["scale60_connect_s"] / base["scale60_connect_s"], 1.0, True))
    latest = _json.loads((Path(results) / "latest.json").read_text())
    cross = latest["cross_host"]["summary"]["1500@1gbit"]
    for key, words in (("rtt_b64_p50_us", "round trip 64 B, p50"),
                       ("fanout4_p99_ms", "Image 30 Hz to 4 hosts, p99")):
        rows.append(("between hosts, 1 Gbit/s", words, "micros_rt_dds", cross["mrt_dds"][key] / cross["rospy"][key],
                     None, True))
    links = latest["constrained_link"]["links"]
    for link, stack, words in (("tbf", "micros_rt_paced", "FIFO link: control p99 beside a camera"),
                               ("htb", "micros_rt", "DSCP link: control p99 beside a camera")):
        p99 = {st: statistics.median(r["control_p99_ms"] for r in links[link][st]) for st in (stack, "rospy")}
        rows.append(("40 Mbit/s link", words, stack, p99[stack] / p99["rospy"], 0.5, True))
    return rows


def plot_summary(rows, path):
    """One picture of :func:`summary_rows`: each figure's ratio to stock rospy (log scale), times on the left
    (lower is better), rates on the right (higher is better), a black tick at the target where there is one."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    from matplotlib.patches import Patch
    from matplotlib.lines import Line2D

    colours = dict(COLOURS, micros_rt_paced="#2ca02c", micros_rt="#1f77b4")
    names = {"micros_rt_shm": "micros_rt, shared memory (its default on one host)",
             "micros_rt_shm_ros2": "micros_rt, shared memory, ROS 2 visibility on",
             "micros_rt_shm_local": "micros_rt, shared memory, ROS 2 visibility off",
             "micros_rt_dds": "micros_rt, DDS", "micros_rt_paced": "micros_rt, camera on paced TCPROS"}
    sides = [[r for r in rows if r[5]], [r for r in rows if not r[5]]]
    fig, axes = plt.subplots(2, 1, figsize=(10, 1.6 + 0.3 * len(rows)),
                             gridspec_kw={"height_ratios": [len(sides[0]) + 1, len(sides[1]) + 1]})
    allv = [v for r in rows for v in (r[3], r[4]) if v] + [1.0]
    lo, hi = min(allv) / 2, max(allv) * 3
    for ax, side, title in zip(axes, sides, ("times: ratio to stock rospy, lower is better",
                                             "rates: ratio to stock rospy, higher is better")):
        ys = list(range(len(side)))[::-1]
        ax.barh(ys, [r[3] for r in side], color=[colours[r[2]] for r in side], height=0.7)
        for y, r in zip(ys, side):
            ax.text(r[3], y, f" {r[3]:.2g}x" if r[3] < 10 else f" {r[3]:.0f}x", va="center", fontsize=8)
            if r[4] is not None:
                ax.plot([r[4], r[4]], [y - 0.45, y + 0.45], color="black", linewidth=2.2)
        ax.set_yticks(ys, [f"{r[0]}: {r[1]}" for r in side], fontsize=8)
        ax.axvline(1.0, color="grey", linewidth=1)
        ax.set_xscale("log")
        ax.set_xlim(lo, hi)
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}x"))
        ax.set_title(title, fontsize=10)
        ax.grid(axis="x", which="major", alpha=0.3)
    stacks = [st for st in names if any(colours[r[2]] == colours[st] for r in rows)]
    handles = [Patch(color=colours[st], label=names[st]) for st in stacks]
    handles += [Line2D([], [], color="black", linewidth=2.2, label="target"),
                Line2D([], [], color="grey", linewidth=1, label="stock rospy (1x)")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle("micros_rt against stock rospy, each ratio measured in one run (benchmarks/results)")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path).name


# =========================================================================== main

def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="1 round, small counts (< 3 min)")
    ap.add_argument("--only", default=",".join(TRANSPORTS), help="comma-separated transports")
    ap.add_argument("--figures", default=",".join(FIGURE_GROUPS), help="comma-separated: " + ",".join(FIGURE_GROUPS))
    ap.add_argument("--rounds", type=int, help="override the number of rounds")
    ap.add_argument("--scale-ns", help="override the scale figure's graph sizes, e.g. 2,10,30,60")
    ap.add_argument("--out", default=str(RESULTS), help="results directory")
    ap.add_argument("--keep-logs", action="store_true")
    ap.add_argument("--summary", action="store_true",
                    help="measure nothing: print README's summary table from the committed results and redraw "
                         "results/summary.png")
    args = ap.parse_args()
    if args.summary:
        rows = summary_rows()
        print("| where (micros_rt's transport) | figure | better | micros_rt / rospy | target |\n|---|---|---|---|---|")
        for section, words, stack, ratio, target, lower in rows:
            where = {"micros_rt_paced": f"{section} (paced TCPROS camera)"}.get(
                stack, f"{section} ({'DDS' if stack in ('micros_rt_dds', 'micros_rt') else 'SHM'})")
            verdict = "—" if target is None else (
                f"{'≤' if lower else '≥'} {target:g}x {'met' if (ratio <= target if lower else ratio >= target) else 'missed'}")
            print(f"| {where} | {words} | {'lower' if lower else 'higher'} | {ratio:.2g}x | {verdict} |"
                  if ratio < 0.1 else f"| {where} | {words} | {'lower' if lower else 'higher'} | {ratio:.2f}x | {verdict} |")
        plot_summary(rows, RESULTS / "summary.png")
        return
    args.only = [t.strip() for t in args.only.split(",") if t.strip()]
    args.figures = [f.strip() for f in args.figures.split(",") if f.strip()]
    for t in args.only:
        if t not in TRANSPORTS:
            ap.error(f"unknown transport {t}; known: {', '.join(TRANSPORTS)}")
    for f in args.figures:
        if f not in FIGURE_GROUPS:
            ap.error(f"unknown figure group {f}; known: {', '.join(FIGURE_GROUPS)}")
    P = dict(PROFILES["quick" if args.quick else "full"])
    if args.rounds:
        P["rounds"] = args.rounds
    if args.scale_ns:
        P["scale_ns"] = tuple(int(x) for x in args.scale_ns.split(","))
    command = "benchmarks/run.py " + " ".join(sys.argv[1:]) if sys.argv[1:] else "benchmarks/run.py"
    outdir = Path(args.out)
    outdir.mkdir(parents=True, exist_ok=True)
    logdir = Path(tempfile.mkdtemp(prefix="micros_rt_bench_"))

    def on_signal(signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_signal)
    t_start = time.monotonic()
    tx0 = eth0_tx()
    b = Bench(args, P, logdir)
    per_round = {}  # (transport, figure) -> [values]
    steps = plan(args, P)
    interrupted = False
    try:
        for i, (rnd, t, label, spec) in enumerate(steps, 1):
            b.prefix = f"[{i}/{len(steps)}] round {rnd + 1}/{P['rounds']} {t}"
            b.progress(label)
            try:
                res = run_step(b, P, t, spec)
            except PhaseError as exc:
                msg = f"round {rnd + 1} {t} {label}: {exc}"
                b.errors.append(msg)
                sys.stderr.write(f"\r\033[K  ! {msg}\n")
                kill_all()
                continue
            for f, v in res.items():
                if v is not None:
                    per_round.setdefault((t, f), []).append(v)
    except KeyboardInterrupt:
        interrupted = True
        sys.stderr.write("\ninterrupted: stopping children, writing what was measured\n")
    finally:
        b.stop()
    wall = time.monotonic() - t_start
    tx1 = eth0_tx()
    eth0 = (tx1 - tx0) if tx0 is not None and tx1 is not None else None
    sys.stderr.write(f"\r\033[Kdone in {wall:.0f} s\n")

    figs, spread = {}, {}
    for (t, f), vs in per_round.items():
        figs.setdefault(t, {})[f] = statistics.median(vs)
        spread.setdefault(t, {})[f] = [min(vs), max(vs), len(vs)]
    for t in figs:  # loss is a count: report the worst round, never a median that hides it
        for f in list(figs[t]):
            if f.endswith("_lost"):
                figs[t][f] = max(per_round[(t, f)])
    transports = [t for t in TRANSPORTS if t in args.only]
    for t in figs:  # one entry per realistic type (the flat keys stay for the table)
        for k, (label, _) in REALISTIC.items():
            e = {x: figs[t].get(f"{k}_{x}") for x in ("p50_us", "p99_us", "rt_lost", "msgs_per_s", "MB_per_s",
                                                      "lost")}
            if any(v is not None for v in e.values()):
                e["max_rate_0_lost_msgs_per_s"] = e["msgs_per_s"] if e["lost"] == 0 else None
                figs[t][label] = e
    mach = machine()
    data = {"machine": mach, "command": ".venv/bin/python " + command, "wall_s": round(wall, 1),
            "rounds": P["rounds"], "interrupted": interrupted,
            "figures": {t: figs.get(t, {}) for t in transports},
            "spread": {t: spread.get(t, {}) for t in transports},
            "config": {t: CONFIG[t] for t in transports},
            "targets": {f: f"{op} {lim}x rospy_tcpros" for f, (lim, op) in TARGETS.items()},
            "errors": b.errors,
            "eth0_tx_packets_during_run": eth0,
            "notes": "figures are medians over rounds (loss: worst round); spread is [min, max, rounds]; "
                     "latency in µs (ping-pong, p50/p99), throughput measured at the receiver over first..last "
                     "message; lost = sent − distinct sequence numbers received after a 2 s drain."}
    previous = outdir / "latest.json"
    try:  # sections other scripts own (OTHER_SECTIONS) stay as they were
        kept = {k: v for k, v in json.loads(previous.read_text()).items() if k in OTHER_SECTIONS}
    except (OSError, ValueError):
        kept = {}
    previous.write_text(json.dumps({**data, **kept}, indent=1) + "\n")
    made = plots(figs, b.samples, transports, outdir)

    tbl = table(figs, spread, transports)
    print(tbl)
    print()
    for t in transports:
        print(f"  {t}: {CONFIG[t]}")
    if b.errors:
        print("\nerrors:")
        for e in b.errors:
            print("  " + e)
    print(f"\neth0 tx packets during the run (whole machine): {eth0}")
    print(f"\nwall time {wall:.0f} s; results in {outdir}/latest.json, latest.md, {', '.join(made)}")

    md = markdown(data, figs, spread, transports, made, b.errors, wall)
    (outdir / "latest.md").write_text("\n".join(md) + "\n")
    if args.keep_logs:
        print(f"logs: {logdir}")
    else:
        shutil.rmtree(logdir, ignore_errors=True)
    return 1 if interrupted else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    finally:
        kill_all()
