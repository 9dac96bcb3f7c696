"""Service calls through ``micros-rt relay``'s ``ros2:`` section against rospy -> rospy, in one run (issue 35,
deliverable 3: p50 through the relay at most 3x a rospy-to-rospy call).

    .venv/bin/python benchmarks/relay_services.py                  # 500 calls per stack, 1 round
    .venv/bin/python benchmarks/relay_services.py --calls 200 --rounds 3

One rosmaster, one stock rospy server (``/bench_ros1``, std_srvs/SetBool, tests/peers/ros1_service_peer.py under
/usr/bin/python3), one rclpy server (``/bench_ros2``, tests/peers/ros2_service_peer.py, Fast DDS), and one relay::

    graph: bench
    ros2:
      export: {/bench_ros1: {}}     # the stock server, offered to ROS 2
      import: {/bench_ros2: {}}     # the rclpy server, offered in the ROS 1 graph

Stacks, run in turn (alternating across rounds), each a client process that waits for the service, makes 20 calls
to warm up, then ``--calls`` calls one after another, each timed as its user sees it:

  rospy_to_rospy        stock rospy client -> the stock server (the reference: master lookup and a new TCP
                        connection per call, as rospy does by default)
  rospy_relay_rclpy     stock rospy client -> the relay (ROS 1 service) -> its ROS 2 helper -> the rclpy server
  rclpy_relay_rospy     rclpy client -> the relay's ROS 2 helper -> the relay -> TCPROS -> the stock server

Loopback-only DDS (benchmarks/*_loopback.xml), this run's own ROS_DOMAIN_ID. Results:
benchmarks/results/relay_services.json and .md. Exit code 0 when every call was answered and both relay stacks'
p50 is at most 3x rospy_to_rospy's.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from services import (RESULTS, bench_env, client_argv, eth0_tx, load, read_events, server_argv,  # noqa: E402
                      start_master, stop)

CLI = str(HERE.parent / ".venv" / "bin" / "micros-rt")
STACKS = {
    "rospy_to_rospy": ("rospy", "/bench_ros1"),
    "rospy_relay_rclpy": ("rospy", "/bench_ros2"),
    "rclpy_relay_rospy": ("rclpy", "/bench_ros1"),
}
TARGET = 3.0


class Relay:
    """``micros-rt relay --json`` in the background; its stdout read on a thread (the latest stats kept)."""

    def __init__(self, config: Path, env: Dict[str, str], log: Any) -> None:
        self.proc = subprocess.Popen([CLI, "relay", "--config", str(config), "--json", "--stats-period", "0.5",
                                      "--poll-period", "0.3"], env=env, stdout=subprocess.PIPE, stderr=log,
                                     text=True, start_new_session=True)
        self.stats: Dict[str, Any] = {}
        self._cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if isinstance(event, dict) and event.get("event") == "stats":
                with self._cond:
                    self.stats = event
                    self._cond.notify_all()

    def wait_carried(self, names: List[str], timeout: float) -> None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                kinds = {e.get("name"): e.get("kind") for e in self.stats.get("ros2", [])}
                if all(kinds.get(n) == "service" for n in names):
                    return
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    raise RuntimeError(f"the relay does not carry {names} after {timeout:g} s: {self.stats}")
                self._cond.wait(left)


def run_client(stack: str, calls: int, env: Dict[str, str], log: Any) -> Dict[str, Any]:
    kind, name = STACKS[stack]
    client = subprocess.Popen(client_argv(kind, name, calls), env=env, stdout=subprocess.PIPE, stderr=log,
                              text=True, start_new_session=True)
    try:
        events = read_events(client, "done", 120 + calls * 0.1)
    finally:
        stop(client)
    measured = [e for e in events if e.get("event") == "summary" and e.get("label") == "measured"]
    if not measured:
        raise RuntimeError(f"{stack}: no measured summary: {events[-3:]}")
    m = measured[0]
    return {"stack": stack, "client": kind, "service": name, "calls": calls, "answered": m["ok"],
            "errors": m["n_errors"], "first_errors": m["errors"], "p50_us": m["p50_us"], "p99_us": m["p99_us"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--out", default=str(RESULTS / "relay_services"))
    args = parser.parse_args()

    env, logdir = bench_env("micros_rt_bench_relay_services_")
    config = logdir / "relay.yaml"
    config.write_text("graph: bench\nros2:\n  export: {/bench_ros1: {}}\n  import: {/bench_ros2: {}}\n")
    log = open(logdir / "processes.log", "w")
    tx0, load0 = eth0_tx(), load()
    master = start_master(env, logdir)
    procs: List["subprocess.Popen[Any]"] = []
    rows: List[Dict[str, Any]] = []
    try:
        for kind, name in (("rospy", "/bench_ros1"), ("rclpy", "/bench_ros2")):
            server = subprocess.Popen(server_argv(kind, name), env=env, stdout=subprocess.PIPE, stderr=log,
                                      text=True, start_new_session=True)
            procs.append(server)
            read_events(server, "ready", 60)
        relay = Relay(config, env, log)
        procs.append(relay.proc)
        relay.wait_carried(["/bench_ros1", "/bench_ros2"], 60)
        for r in range(args.rounds):
            order = list(STACKS) if r % 2 == 0 else list(reversed(STACKS))
            for stack in order:
                row = run_client(stack, args.calls, env, log)
                row["round"] = r
                rows.append(row)
                print(f"round {r} {stack:18s} answered {row['answered']}/{row['calls']}  "
                      f"p50 {row['p50_us']:8.0f} us  p99 {row['p99_us']:8.0f} us", flush=True)
        relay_stats = relay.stats.get("ros2", [])
    finally:
        for proc in reversed(procs):
            stop(proc)
        stop(master)
        log.close()
    tx1, load1 = eth0_tx(), load()

    def median(values: List[float]) -> float:
        values = sorted(values)
        return values[len(values) // 2]

    summary: Dict[str, Dict[str, Any]] = {}
    for stack in STACKS:
        mine = [row for row in rows if row["stack"] == stack]
        summary[stack] = {"p50_us": median([row["p50_us"] for row in mine]),
                          "p99_us": median([row["p99_us"] for row in mine]),
                          "answered": sum(row["answered"] for row in mine), "calls": sum(row["calls"] for row in mine)}
    ref = summary["rospy_to_rospy"]["p50_us"]
    for s in summary.values():
        s["p50_vs_rospy"] = s["p50_us"] / ref if ref else None
    result = {"date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "calls": args.calls,
              "rounds": args.rounds, "load_before": load0, "load_after": load1,
              "eth0_tx_delta": (tx1 - tx0) if tx0 is not None and tx1 is not None else None,
              "rows": rows, "summary": summary, "relay_counters": relay_stats, "target": TARGET}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [f"# Service calls through micros-rt relay's ros2: section ({result['date']}, {args.calls} calls x "
             f"{args.rounds} round(s), loopback, load {load0:.2f} -> {load1:.2f}, eth0 packets sent meanwhile: "
             f"{result['eth0_tx_delta']})", "",
             "| stack | answered | p50 (us) | p99 (us) | p50 / rospy's |", "| --- | --- | --- | --- | --- |"]
    for stack, s in summary.items():
        ratio = "" if s["p50_vs_rospy"] is None else f"{s['p50_vs_rospy']:.2f}"
        lines.append(f"| {stack} | {s['answered']}/{s['calls']} | {s['p50_us']:.0f} | {s['p99_us']:.0f} | {ratio} |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    shutil.rmtree(logdir, ignore_errors=True)
    ok = all(s["answered"] == s["calls"] for s in summary.values()) and all(
        (s["p50_vs_rospy"] or 0) <= TARGET for k, s in summary.items() if k != "rospy_to_rospy")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
