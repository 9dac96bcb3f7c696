#!/usr/bin/env python3
"""A 640x480 rgb8 camera at 30 Hz into an rclpy subscriber (issue 43, deliverable 3): frames received, rate and
latency, and where the time goes.

    flock /tmp/micros_rt-bench.lock .venv/bin/python benchmarks/camera_ros2.py [--seconds 10] [--rounds 2]
        [--stacks mrt,rclpy,relay,...] [--out benchmarks/results/camera_ros2]

Stacks (each a publisher process and one rclpy subscriber, Fast DDS on loopback, a rosmaster of its own, its own
DDS domain, separate processes):

- ``rclpy``: an rclpy publisher (the reference: ROS 2 to ROS 2 on one host; Fast DDS then uses shared memory);
- ``rclpy_udp``: the same with Fast DDS on UDP only (what a Cyclone writer's data takes into Fast DDS);
- ``mrt``: a micros_rt node's ``advertise`` (the defaults), its DDS writer read by the rclpy node;
- ``mrt_rcvbuf``: the same, the subscriber's Fast DDS given a 4 MB socket receive buffer (its profile's
  ``receiveBufferSize``): whether the subscriber's socket is where frames wait;
- ``relay``: a stock rospy publisher, ``micros-rt relay`` exporting the topic to ROS 2.

The publisher stamps each frame's ``header.stamp`` with the wall clock just before publishing and numbers it in
``header.frame_id``; the subscriber's callback takes the difference to its wall clock (one host, one clock) and
counts the frames it never got. Each stack runs ``--seconds`` once the subscriber matched, ``--rounds`` times,
stacks alternating. Also counted: the UDP datagrams the subscriber's sockets dropped (``/proc/<pid>/net/udp``'s
``drops``, before and after), i.e. fragments the kernel threw away because the socket's receive buffer was full.
Results: ``<out>.json`` and ``<out>.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
import harness  # noqa: E402  (a rosmaster of our own, loopback DDS settings, free ports)

TOPIC = "/camera/image"
W, H = 640, 480

SUBSCRIBER = r'''
import json, os, sys, time, threading
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import Image
rclpy.init()
node = rclpy.create_node("camera_sub_%d" % os.getpid())
lat, seqs = [], []
first = [None]
def cb(m):
    now = time.time()
    lat.append(now - (m.header.stamp.sec + m.header.stamp.nanosec * 1e-9))
    seqs.append(int(m.header.frame_id))
    if first[0] is None:
        first[0] = now
qos = QoSProfile(depth=int(sys.argv[2]), history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
node.create_subscription(Image, sys.argv[1], cb, qos)
print(json.dumps({"ev": "ready", "pid": os.getpid()}), flush=True)
def stdin():
    for line in sys.stdin:
        if line.strip() == "report":
            print(json.dumps({"ev": "report", "lat": lat, "seqs": seqs, "first": first[0], "last": time.time()}),
                  flush=True)
    os._exit(0)
threading.Thread(target=stdin, daemon=True).start()
rclpy.spin(node)
'''

PUBLISHER_RCLPY = r'''
import json, os, sys, time
import rclpy
from sensor_msgs.msg import Image
rclpy.init()
node = rclpy.create_node("camera_pub_%d" % os.getpid())
pub = node.create_publisher(Image, sys.argv[1], 10)
seconds, rate = float(sys.argv[2]), float(sys.argv[3])
while pub.get_subscription_count() < 1:
    rclpy.spin_once(node, timeout_sec=0.05)
time.sleep(1.0)
data = bytes(640 * 480 * 3)
m = Image(height=480, width=640, encoding="rgb8", step=640 * 3, data=data)
n, t0 = 0, time.monotonic()
print(json.dumps({"ev": "start"}), flush=True)
while time.monotonic() - t0 < seconds:
    m.header.frame_id = str(n)
    now = time.time()
    m.header.stamp.sec, m.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    pub.publish(m)
    n += 1
    time.sleep(max(0.0, t0 + n / rate - time.monotonic()))
time.sleep(1.0)
print(json.dumps({"ev": "done", "sent": n}), flush=True)
'''

PUBLISHER_ROS1 = r'''
import json, os, sys, time
USE_MRT = sys.argv[4] == "mrt"
if USE_MRT:
    import micros_rt as rospy_like
else:
    import rospy as rospy_like
import rospy
from sensor_msgs.msg import Image
if USE_MRT:
    rospy_like.init_node("camera_pub", anonymous=True, disable_rosout=True)
    pub = rospy_like.NodeHandle().advertise(sys.argv[1], Image, 10)
else:
    rospy.init_node("camera_pub", anonymous=True, disable_rosout=True)
    pub = rospy.Publisher(sys.argv[1], Image, queue_size=10)
seconds, rate = float(sys.argv[2]), float(sys.argv[3])
deadline = time.monotonic() + 60
while pub.get_num_connections() < 1 and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(1.0)
m = Image(height=480, width=640, encoding="rgb8", step=640 * 3, data=bytes(640 * 480 * 3))
n, t0 = 0, time.monotonic()
print(json.dumps({"ev": "start"}), flush=True)
while time.monotonic() - t0 < seconds:
    m.header.frame_id = str(n)
    m.header.stamp = rospy.Time.from_sec(time.time())
    pub.publish(m)
    n += 1
    time.sleep(max(0.0, t0 + n / rate - time.monotonic()))
time.sleep(1.0)
print(json.dumps({"ev": "done", "sent": n}), flush=True)
'''

RCVBUF_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>udp_lo</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
      <receiveBufferSize>{rcvbuf}</receiveBufferSize>
      <sendBufferSize>{rcvbuf}</sendBufferSize>
    </transport_descriptor>
    {shm}
  </transport_descriptors>
  <participant profile_name="loopback" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>udp_lo</transport_id>
        {shm_ref}
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""
SHM_DESCRIPTOR = "<transport_descriptor><transport_id>shm</transport_id><type>SHM</type></transport_descriptor>"


def fastdds_profile(path: Path, *, rcvbuf: int = 0, shm: bool = True) -> Path:
    path.write_text(RCVBUF_PROFILE.format(rcvbuf=rcvbuf, shm=SHM_DESCRIPTOR if shm else "",
                                          shm_ref="<transport_id>shm</transport_id>" if shm else ""))
    return path


def udp_drops(pid: int) -> int:
    """Datagrams the kernel dropped on ``pid``'s UDP sockets (full receive buffer), from /proc/<pid>/net/udp by
    the process's socket inodes."""
    try:
        inodes = set()
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
        total = 0
        for table in ("udp", "udp6"):
            with open(f"/proc/{pid}/net/{table}") as f:
                for line in f.readlines()[1:]:
                    parts = line.split()
                    if len(parts) >= 13 and parts[9] in inodes:
                        total += int(parts[12])
        return total
    except OSError:
        return -1


def _read_event(proc: "subprocess.Popen[str]", ev: str, timeout: float) -> Dict[str, Any]:
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"process exited before {ev!r}: {proc.args!r}")
        try:
            data = json.loads(line)
        except ValueError:
            continue
        if data.get("ev") == ev:
            return dict(data)
    raise RuntimeError(f"no {ev!r} within {timeout} s")


def _stop(proc: "subprocess.Popen[str]") -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def run_stack(stack: str, seconds: float, rate: float, depth: int, work: Path, domain: int,
              extra: Dict[str, str]) -> Dict[str, Any]:
    work.mkdir(parents=True, exist_ok=True)
    master = harness.RosMaster(workdir=work / f"master_{stack}", domain_id=domain).start()
    env = dict(master.env)
    env["PYTHONUNBUFFERED"] = "1"
    if stack.startswith("mrt") or stack == "relay":
        # what a user gets: ROS_IP=127.0.0.1 and no CYCLONEDDS_URI (micros_rt's own loopback configuration); a
        # variant of --mrt-config adds its XML after it (Cyclone: later sources win)
        env.pop("CYCLONEDDS_URI", None)
        name = stack.partition("_")[2]
        if name in extra:
            # loopback only, as micros_rt's own loopback configuration (a CYCLONEDDS_URI replaces it), then the XML
            xml = work / f"{name}.xml"
            xml.write_text(f'<CycloneDDS><Domain id="any">{extra[name]}</Domain></CycloneDDS>')
            env["CYCLONEDDS_URI"] = f"{harness.CYCLONEDDS_CONFIG.as_uri()},{xml.as_uri()}"
    sub_env = dict(env)
    if stack == "mrt_rcvbuf":
        sub_env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(fastdds_profile(work / "rcvbuf.xml", rcvbuf=4 << 20))
    if stack == "rclpy_udp":
        sub_env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(fastdds_profile(work / "udp.xml", shm=False))
    procs: List["subprocess.Popen[str]"] = []
    try:
        sub = subprocess.Popen([harness.ROS2_PYTHON, "-c", SUBSCRIBER, TOPIC, str(depth)], env=sub_env,
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        procs.append(sub)
        sub_pid = _read_event(sub, "ready", 60)["pid"]
        if stack in ("rclpy", "rclpy_udp"):
            pub_argv = [harness.ROS2_PYTHON, "-c", PUBLISHER_RCLPY, TOPIC, str(seconds), str(rate)]
            pub_env = sub_env
        elif stack == "relay":
            config = work / "relay.yaml"
            config.write_text(f"graph: camera\nros2:\n  export: {{{TOPIC}: {{}}}}\n")
            procs.append(subprocess.Popen([str(ROOT / ".venv" / "bin" / "micros-rt"), "relay", "--config", str(config),
                                           "--poll-period", "0.3"], env=env, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL, text=True))
            pub_argv = [harness.STOCK_PYTHON, "-c", PUBLISHER_ROS1, TOPIC, str(seconds), str(rate), "rospy"]
            pub_env = env
        else:
            pub_argv = [str(ROOT / ".venv" / "bin" / "python"), "-c", PUBLISHER_ROS1, TOPIC, str(seconds), str(rate),
                        "mrt"]
            pub_env = env
        pub = subprocess.Popen(pub_argv, env=pub_env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
        procs.append(pub)
        _read_event(pub, "start", 90)
        drops0 = udp_drops(sub_pid)
        sent = _read_event(pub, "done", seconds + 60)["sent"]
        drops1 = udp_drops(sub_pid)
        assert sub.stdin is not None
        sub.stdin.write("report\n")
        sub.stdin.flush()
        report = _read_event(sub, "report", 30)
    finally:
        for p in reversed(procs):
            _stop(p)
        master.cleanup()
    lat = sorted(report["lat"])
    seqs = report["seqs"]
    received = len(seqs)

    def pct(q: float) -> Optional[float]:
        return round(lat[min(len(lat) - 1, int(q * len(lat)))] * 1e3, 2) if lat else None

    return {"stack": stack, "sent": sent, "received": received, "missing": sent - len(set(seqs)),
            "rate_hz": round(received / seconds, 2),
            "p50_ms": pct(0.50), "p99_ms": pct(0.99), "max_ms": pct(1.0),
            "mean_ms": round(statistics.fmean(lat) * 1e3, 2) if lat else None,
            "subscriber_udp_drops": drops1 - drops0 if drops0 >= 0 and drops1 >= 0 else None}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--depth", type=int, default=10, help="the rclpy subscriber's history depth")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--stacks", default="rclpy,rclpy_udp,mrt,mrt_rcvbuf,relay")
    ap.add_argument("--mrt-config", action="append", default=[], metavar="NAME=XML",
                    help="a stack mrt_NAME: micros_rt with this Cyclone XML (inside <Domain>) added to its own")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "camera_ros2"))
    args = ap.parse_args()
    stacks = [s for s in args.stacks.split(",") if s]
    extra = dict(item.split("=", 1) for item in args.mrt_config)
    stacks += [f"mrt_{name}" for name in extra if f"mrt_{name}" not in stacks]
    domain = harness.dds_domain_id_for_pid()
    eth0 = harness.eth0_tx_packets()
    load0 = os.getloadavg()[0]
    started = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    results: List[Dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="camera_ros2_") as tmp:
        for r in range(args.rounds):
            for stack in stacks:
                res = run_stack(stack, args.seconds, args.rate, args.depth, Path(tmp) / f"{r}_{stack}", domain,
                                extra)
                res["round"] = r
                results.append(res)
                print(json.dumps(res), flush=True)
    eth1 = harness.eth0_tx_packets()
    meta = {"started": started, "seconds": args.seconds, "rate": args.rate, "depth": args.depth,
            "rounds": args.rounds, "load_start": round(load0, 2), "load_end": round(os.getloadavg()[0], 2),
            "eth0_tx_packets": None if eth0 is None or eth1 is None else eth1 - eth0}
    Path(args.out + ".json").write_text(json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    lines = [f"# 640x480 rgb8 at {args.rate:g} Hz into an rclpy subscriber (depth {args.depth}), {started}",
             "", f"{args.seconds:g} s per stack, {args.rounds} rounds, load {meta['load_start']} -> {meta['load_end']},"
             f" eth0 packets sent meanwhile: {meta['eth0_tx_packets']}", "",
             "| stack | round | sent | received | missing | frames/s | p50 ms | p99 ms | max ms | subscriber UDP drops |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        lines.append(f"| {res['stack']} | {res['round']} | {res['sent']} | {res['received']} | {res['missing']} | "
                     f"{res['rate_hz']} | {res['p50_ms']} | {res['p99_ms']} | {res['max_ms']} | "
                     f"{res['subscriber_udp_drops']} |")
    Path(args.out + ".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
