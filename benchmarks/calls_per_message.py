#!/usr/bin/env python3
"""Python function calls per received 64 B message, counted in every thread of the subscriber's process.

    flock /tmp/micros_rt-bench.lock .venv/bin/python benchmarks/calls_per_message.py [--count 2000] [--rate 500]
    ... --rate 10 --count 100 --skip 20 --out calls_per_message_10hz.json    # each message a wake of its own

Each case is a publisher and a subscriber in separate processes beside a rosmaster of its own (loopback, its own
DDS domain): stock rospy to stock rospy (TCPROS, under /usr/bin/python3), micros_rt to micros_rt under the defaults
(shared memory), stock rospy to micros_rt (TCPROS into micros_rt's admission path), micros_rt to micros_rt with
a time filter, a deadline and source order asked for (the admission options ask for), and micros_rt to micros_rt
over DDS (shared memory off, ROS 2 visibility on: the plane between hosts, loopback-only Cyclone). The subscriber installs a profile
function in every thread before any is started (``threading.setprofile``) and counts Python ``call`` events while
its window is open (``CALLS_BY_FUNCTION=1``: and prints them by function): from its ``--skip``-th message to ``--count`` messages later. The count is deterministic up to
the housekeeping threads' ticks inside the window (a few per second), so the publisher sends at ``--rate``.
Prints a table and writes ``benchmarks/results/calls_per_message.json`` (``--out``: another name there).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from pathlib import Path
from typing import Dict, Optional

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
MRT = str(REPO / ".venv/bin/python")
ROSPY = "/usr/bin/python3"

_SUB = r'''
import collections, json, os, sys, threading, time
BY = collections.Counter() if os.environ.get("CALLS_BY_FUNCTION") else None
COUNT, SKIP, KIND, TOPIC, OPTS = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
calls = [0]
state = {"on": False, "n": 0, "t0": 0.0}

def prof(frame, event, arg):
    if event == "call" and state["on"]:
        calls[0] += 1
        if BY is not None:
            code = frame.f_code
            BY[f"{code.co_filename.rsplit('/', 2)[-2:]} {code.co_name}"] += 1

threading.setprofile(prof)
done = threading.Event()

def cb(msg):
    n = state["n"] = state["n"] + 1
    if n == SKIP:
        state["t0"] = time.monotonic()
        state["on"] = True
        sys.setprofile(prof)
    elif n == SKIP + COUNT:
        state["on"] = False
        state["t1"] = time.monotonic()
        done.set()

from std_msgs.msg import String
if KIND == "rospy":
    import rospy
    rospy.init_node("calls_sub", disable_signals=True)
    sub = rospy.Subscriber(TOPIC, String, cb, queue_size=None if OPTS == "lossless" else 1000)
else:
    import micros_rt
    micros_rt.init_node("calls_sub", disable_signals=True)
    nh = micros_rt.NodeHandle()
    if OPTS == "qos":
        sub = nh.subscribe_with_qos(TOPIC, String, cb, 1000, micros_rt.SubscribeQoSOptions(
            deadline=5.0, time_filter_duration=0.0001, ordered_by_sending_timestamp=True))
    else:
        sub = nh.subscribe(TOPIC, String, cb, 1000)
print("READY", flush=True)
if not done.wait(120):
    print(json.dumps({"error": "timed out", "got": state["n"]}), flush=True)
    sys.exit(1)
links = {} if KIND == "rospy" else sub.connection_transports()
dds_reader = False if KIND == "rospy" else any(s["dds_reader"] for s in __import__("micros_rt.core.introspection", fromlist=["x"]).node_info()["subscriptions"])
print(json.dumps({"calls": calls[0], "count": COUNT, "seconds": state["t1"] - state["t0"],
                  "links": sorted(set(links.values())), "dds_reader": dds_reader,
                  "by_function": None if BY is None else [(k, v / COUNT) for k, v in BY.most_common(40)]}), flush=True)
'''

_PUB = r'''
import sys, time
RATE, KIND, TOPIC = float(sys.argv[1]), sys.argv[2], sys.argv[3]
from std_msgs.msg import String
if KIND == "rospy":
    import rospy
    rospy.init_node("calls_pub", disable_signals=True)
    pub = rospy.Publisher(TOPIC, String, queue_size=1000)
else:
    import micros_rt
    micros_rt.init_node("calls_pub", disable_signals=True)
    pub = micros_rt.NodeHandle().advertise(TOPIC, String, 1000)
while pub.get_num_connections() < 1:
    time.sleep(0.05)
time.sleep(1.0)  # the link settled (a subscriber's own negotiation, its first housekeeping)
msg = String(data="x" * 60)  # 64 B on the wire with the length prefix
period, t = 1.0 / RATE, time.monotonic()
while True:
    pub.publish(msg)
    t += period
    delay = t - time.monotonic()
    if delay > 0:
        time.sleep(delay)
'''

#: the DDS plane between two nodes of this host, as between hosts (shared memory off, ROS 2 visibility on)
_DDS = {"MICROS_RT_DISABLE_SHM": "1", "MICROS_RT_ROS2": "on"}
CASES = (
    ("rospy -> rospy (TCPROS)", "rospy", "rospy", "plain", {}),
    ("micros_rt -> micros_rt (defaults: SHM)", "mrt", "mrt", "plain", {}),
    ("rospy -> micros_rt (TCPROS)", "rospy", "mrt", "plain", {}),
    ("micros_rt -> micros_rt, time filter + deadline + source order", "mrt", "mrt", "qos", {}),
    ("micros_rt -> micros_rt over DDS (SHM off, ROS 2 visibility on)", "mrt", "mrt", "plain", _DDS),
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env(master: str, domain: int, mrt: bool, extra: Optional[Dict[str, str]] = None) -> dict:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "CYCLONEDDS", "MICROS_RT", "PYTHONPATH"))}
    env.update(ROS_MASTER_URI=master, ROS_IP="127.0.0.1", ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1",
               ROS_HOME=str(Path(tempfile.gettempdir()) / "micros_rt_calls_roshome"))
    if mrt:
        env["PYTHONPATH"] = str(REPO)
        env.update(extra or {})
        if "MICROS_RT_DISABLE_SHM" in env:  # DDS between the nodes: loopback only, as the tests configure it
            env["CYCLONEDDS_URI"] = (REPO / "tests" / "cyclonedds_loopback.xml").as_uri()
    return env


def run_case(pub_kind: str, sub_kind: str, opts: str, *, count: int, skip: int, rate: float, domain: int,
             extra: Dict[str, str]) -> dict:
    port = _free_port()
    master = f"http://127.0.0.1:{port}"
    procs = [subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)], env=_env(master, domain, False),
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        end = time.monotonic() + 20
        while True:
            try:
                xmlrpc.client.ServerProxy(master).getSystemState("/calls")
                break
            except OSError:
                if time.monotonic() > end:
                    raise SystemExit("rosmaster did not come up")
                time.sleep(0.1)
        topic = "/calls_chatter"
        log = open(Path(tempfile.gettempdir()) / "micros_rt_calls_sub.log", "w")
        sub = subprocess.Popen([MRT if sub_kind == "mrt" else ROSPY, "-c", _SUB, str(count), str(skip),
                                sub_kind, topic, opts], env=_env(master, domain, sub_kind == "mrt", extra), text=True,
                               stdout=subprocess.PIPE, stderr=log, start_new_session=True)
        procs.append(sub)
        assert sub.stdout is not None
        while "READY" not in (sub.stdout.readline() or "READY"):
            pass
        procs.append(subprocess.Popen([MRT if pub_kind == "mrt" else ROSPY, "-c", _PUB, str(rate), pub_kind, topic],
                                      env=_env(master, domain, pub_kind == "mrt", extra), stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        for line in sub.stdout:
            if line.startswith("{"):
                out: dict = json.loads(line)
                return out
        raise SystemExit(f"the subscriber ended without a result (its log: {log.name})")
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=2000)
    ap.add_argument("--skip", type=int, default=200)
    ap.add_argument("--rate", type=float, default=500.0)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--only", default="", help="run the cases whose name contains this")
    ap.add_argument("--out", default="calls_per_message.json",
                    help="file name under benchmarks/results/ (e.g. calls_per_message_10hz.json for --rate 10)")
    args = ap.parse_args()
    rows = []
    domain = 100 + os.getpid() % 100
    for name, pub_kind, sub_kind, opts, extra in CASES:
        if args.only not in name:
            continue
        per = []
        links: list = []
        for _ in range(args.rounds):
            out = run_case(pub_kind, sub_kind, opts, count=args.count, skip=args.skip, rate=args.rate, domain=domain,
                           extra=extra)
            per.append(out["calls"] / out["count"])
            if out.get("by_function"):
                for fn, n in out["by_function"]:
                    print(f"    {n:6.2f}  {fn}")
            links = out["links"] + (["a DDS reader too"] if out.get("dds_reader") else [])
        rows.append({"case": name, "calls_per_message": per, "links": links})
        print(f"{name:64s} {' '.join(f'{c:6.1f}' for c in per)}  {links}", flush=True)
    if args.only:
        return
    base = min(rows[0]["calls_per_message"])
    for row in rows[1:]:
        print(f"{row['case']:64s} {min(row['calls_per_message']) / base:.2f}x rospy's")
    results = HERE / "results"
    results.mkdir(exist_ok=True)
    (results / args.out).write_text(json.dumps(
        {"count": args.count, "rate": args.rate, "rows": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S")},
        indent=1) + "\n")


if __name__ == "__main__":
    sys.exit(main())
