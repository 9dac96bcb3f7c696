#!/usr/bin/env python3
"""Two robots, stock ROS nodes, one shaped link: what ``micros-rt relay`` does (README, "Robots and stock
nodes"). Run it as root (it makes network namespaces): ``./scripts/relay_demo.sh [--seconds 10]``.

Robot A and robot B are network namespaces joined by a veth pair; A's egress is shaped by ``tc tbf`` to
40 Mbit/s with a 50 ms queue (a radio link's bottleneck). Each robot has its own rosmaster. On A a stock rospy
node (no micros_rt) publishes /control (geometry_msgs/PointStamped, 1 kHz) and /camera/image
(sensor_msgs/Image 640x480 rgb8, 30 Hz: 221 Mbit/s, five times the link); on B a stock rospy node subscribes
to both. Between the two graphs only the relays talk, over DDS: A's relay exports the two topics with the QoS
its configuration gives them, B's relay publishes them in B's graph. The demo prints the two configurations
(the lesson: that is all there is to set up), then once per second what B's stock subscriber receives, then a
summary and the relays' own counters (``micros-rt relay --json``).

The set-up (namespaces, veth, tbf, rosmasters) is benchmarks/constrained_link.py's ``Link`` and the nodes are
tests/peers/mrt_link.py, as in that benchmark's ``--stacks relay_capped`` run. Everything the demo starts is
stopped and removed when it ends, also after Ctrl-C or an error; nothing leaves the namespaces (eth0's
transmitted packets are counted before and after).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import FrameType
from typing import IO, Any, Dict, List, Optional

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from constrained_link import PEER, STOCK_PYTHON, Link, eth0_tx  # noqa: E402

MICROS_RT = str(ROOT / ".venv" / "bin" / "micros-rt")

# Robot A's relay: which topics of A's graph leave it, and with which QoS on the link.
RELAY_A = """\
graph: robot_a                    # outside A these are /robot_a/control and /robot_a/camera/image
export:
  /control: {transport_priority: HIGH, queue_size: 100}             # DSCP AF41: first where honoured
  /camera/image: {using_best_effort_protocol: true, max_rate: %g}    # newest frames only, at most %g Hz
link_bandwidth: 40Mbit            # the link's rate: the camera's process keeps its queue in it short
"""
# Robot B's relay: which other graphs' topics B's graph gets, under which names.
RELAY_B = """\
graph: robot_b
import:
  /robot_a/control: {as: /control, queue_size: 100}
  /robot_a/camera/image: {as: /camera/image, queue_size: 2}
"""


class Process:
    """A process in one robot's namespace whose stdout is one JSON event per line, read by a thread."""

    def __init__(self, link: Link, robot: int, name: str, argv: List[str], log: Path) -> None:
        self.name, self.log = name, log
        self._stderr: IO[str] = open(log, "w")
        self.proc = link.run(robot, argv, stderr=self._stderr)
        self.events: "queue.Queue[Dict[str, Any]]" = queue.Queue()
        self.ended = threading.Event()  # its stdout closed: every event it printed is in self.events
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                self.events.put(json.loads(line))
            except ValueError:
                continue
        self.ended.set()

    def wait_for(self, event: str, timeout: float, what: str) -> Dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            try:
                found = self.events.get(timeout=max(0.0, min(0.5, deadline - time.monotonic())))
                if found.get("event") == event:
                    return found
            except queue.Empty:
                if self.ended.is_set():
                    try:
                        code: Any = self.proc.wait(5)
                    except subprocess.TimeoutExpired:
                        code = "none yet"
                    raise DemoError(f"{self.name} exited (code {code}) while the demo waited for {what}; its "
                                    f"errors:\n" + self.tail()) from None
            if time.monotonic() >= deadline:
                raise DemoError(f"{self.name}: waited {timeout:.0f} s for {what}, in vain; its errors:\n" + self.tail())

    def tail(self) -> str:
        text = self.log.read_text(errors="replace").strip().splitlines()[-15:]
        return "\n".join("    " + line for line in text) or "    (nothing on stderr)"

    def stop(self, timeout: float = 10.0) -> None:
        """SIGINT (a relay then prints its final counters), SIGTERM, SIGKILL."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.proc.poll() is not None:
                break
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                continue
        self._stderr.close()


class DemoError(Exception):
    """Something the demo needs did not happen; the message says what and shows the process's errors."""


def last_stats(relay: Process) -> Optional[Dict[str, Any]]:
    stats = None
    while not relay.events.empty():
        event = relay.events.get()
        if event.get("event") == "stats":
            stats = event
    return stats


def ms(value: Any) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.1f} ms"


def counters(entry: Dict[str, Any]) -> str:
    return ", ".join(f"{k} {v:,}" for k, v in entry.items() if isinstance(v, int) and not isinstance(v, bool))


def run(args: argparse.Namespace, link: Link, work: Path, started: List[Process]) -> int:
    configs = {"robot_a": RELAY_A % (args.camera_rate, args.camera_rate), "robot_b": RELAY_B}
    for graph, text in configs.items():
        (work / f"relay_{graph}.yaml").write_text(text)
        print(f"--- relay_{graph}.yaml\n{text}", end="")
    print(f"--- two robots: namespaces {link.ns[0]} (A, {link.ip[0]}) and {link.ns[1]} (B, {link.ip[1]}), each "
          f"its own rosmaster; A's egress: tc tbf rate 40mbit burst 32kbit latency 50ms", flush=True)
    link.up()

    def start(robot: int, name: str, argv: List[str]) -> Process:
        started.append(Process(link, robot, name, argv, work / f"{name.replace(' ', '_')}.log"))
        return started[-1]

    relays = []
    for robot, graph in enumerate(configs):
        print(f"robot {'AB'[robot]}: ROS_MASTER_URI={link.env(robot)['ROS_MASTER_URI']} micros-rt relay --config "
              f"relay_{graph}.yaml", flush=True)
        relays.append(start(robot, f"relay {graph}", [MICROS_RT, "relay", "--config", str(work / f"relay_{graph}.yaml"),
                                                      "--json", "--stats-period", "1", "--poll-period", "0.3"]))
    for relay in relays:
        relay.wait_for("ready", 60, "it to start")
    image = ["--image-topic", "/camera/image", "--width", "640", "--height", "480"]
    sub = start(1, "robot B's subscriber", [STOCK_PYTHON, str(PEER), "sub", "--stock", "--seconds",
                                            str(args.seconds + 120), "--progress-period", "1", *image])
    sub.wait_for("ready", 60, "it to start")
    go = work / "go"
    pub = start(0, "robot A's publisher", [STOCK_PYTHON, str(PEER), "pub", "--stock", "--seconds", str(args.seconds),
                                           "--start-file", str(go), *image])
    print("robot A: stock rospy node publishing /control (1 kHz) and /camera/image (640x480, 30 Hz)\n"
          "robot B: stock rospy node subscribing to /control and /camera/image", flush=True)
    pub.wait_for("ready", 90, "it to start")
    sub.wait_for("connected", 90, "its connection to B's relay")
    go.touch()  # both relays carry the topics: A starts publishing
    print(f"at robot B's subscriber, every second ({args.seconds:g} s):", flush=True)
    for second in range(1, math.ceil(args.seconds) + 1):
        p = sub.wait_for("progress", 30, "a second's messages")
        print(f"  {second:3d} s  /control {p['control']:5,}/s  latency p50 {ms(p['p50_ms']):>8}  "
              f"p99 {ms(p['p99_ms']):>8}   /camera/image {p['image']:2d} frames/s", flush=True)
    published = pub.wait_for("published", 60, "the end of publishing")
    summary = sub.wait_for("summary", 60, "its summary")
    print(f"summary, robot A published -> robot B's stock subscriber received:\n"
          f"  /control       {published['control']:,} -> {summary['control']:,}, latency p50 {ms(summary['p50_ms'])}, "
          f"p99 {ms(summary['p99_ms'])}, max {ms(summary['max_ms'])}\n"
          f"  /camera/image  {published['image']:,} -> {summary['image']:,} frames "
          f"({summary['image'] / max(published['seconds'], 1e-9):.1f} per second)", flush=True)
    print("relay counters (micros-rt relay --json, final 'stats' event):")
    for relay in relays:
        relay.stop()
        stats = last_stats(relay)
        if stats is None:
            raise DemoError(f"{relay.name} printed no counters; its errors:\n" + relay.tail())
        for kind in ("exports", "imports"):
            for entry in stats.get(kind, []):
                print(f"  {stats['graph']} {kind[:-1]} {entry['topic']} as {entry['as']}: {counters(entry)}")
    return 0 if summary["control"] > 0 and summary["image"] > 0 else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0, help="how long robot A publishes")
    ap.add_argument("--camera-rate", type=float, default=2.0,
                    help="the camera export's max_rate (Hz); a 640x480 rgb8 frame is 7.4 Mbit: 5 Hz is 37 Mbit/s "
                         "of the 40")
    args = ap.parse_args()
    if os.geteuid() != 0:
        print("relay_demo.py: makes two network namespaces (the robots) and a tc qdisc: run it as root "
              "(sudo ./scripts/relay_demo.sh)", file=sys.stderr)
        return 2
    if args.seconds <= 0 or args.camera_rate <= 0:
        ap.error("--seconds and --camera-rate must be positive")

    def interrupted(signum: int, frame: Optional[FrameType]) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupted)
    signal.signal(signal.SIGHUP, interrupted)
    pid = os.getpid()
    link = Link("tbf", masters=2, names=[f"robot_a_{pid}", f"robot_b_{pid}"])
    work = Path(f"/tmp/{link.ns[0]}")  # also the robots' ROS_HOME (rosmaster logs): removed at the end
    work.mkdir(parents=True, exist_ok=True)
    started: List[Process] = []
    tx_before = eth0_tx()
    code = 1
    try:
        code = run(args, link, work, started)
    except KeyboardInterrupt:
        print("relay_demo: interrupted", file=sys.stderr)
        code = 130
    except (DemoError, SystemExit, subprocess.SubprocessError, OSError) as exc:
        print(f"relay_demo: {exc}", file=sys.stderr)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(sig, signal.SIG_IGN)  # a second Ctrl-C does not leave namespaces behind
        for proc in reversed(started):
            proc.stop(5.0)
        link.down()
        shutil.rmtree(work, ignore_errors=True)
        tx_after = eth0_tx()
        left = [ns for ns in link.ns if ns in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                                             text=True).stdout.split()]
        print(f"eth0 tx packets during the demo: "
              f"{'n/a' if tx_before is None or tx_after is None else tx_after - tx_before}")
        print(f"removed namespaces {link.ns[0]} and {link.ns[1]}" if not left else f"left behind: {left}")
    return code


if __name__ == "__main__":
    sys.exit(main())
