"""Service call latency, micros_rt <-> rclpy against rospy <-> rospy (issue 35's service target), one run.

    .venv/bin/python benchmarks/services.py                 # 1,000 calls per stack, 1 round
    .venv/bin/python benchmarks/services.py --calls 200 --rounds 3

Every stack is a server process and a client process (tests/peers/ros1_service_peer.py with stock rospy or
micros_rt, tests/peers/ros2_service_peer.py with rclpy and Fast DDS), std_srvs/SetBool, one rosmaster, loopback-only
DDS (benchmarks/cyclonedds_loopback.xml, benchmarks/fastdds_loopback.xml), this run's own ROS_DOMAIN_ID. The client
waits for the service, makes 20 calls to warm up, then ``--calls`` calls one after another, each timed around the
call as its user sees it (rospy's ServiceProxy: a master lookup and a new TCP connection per call, as rospy does by
default; rclpy: call_async and a wait for the future). Stacks run in turn, alternating across rounds:

  rospy_to_rospy    stock rospy client -> stock rospy server (the reference of the target)
  mrt_to_rclpy      micros_rt service_client -> rclpy server (through micros_rt's ROS 2 helper)
  rclpy_to_mrt      rclpy client -> micros_rt advertise_service (through micros_rt's ROS 2 helper)
  rclpy_to_rclpy    rclpy client -> rclpy server (what ROS 2 itself costs here, for context)

Target: every call answered, and p50 of mrt_to_rclpy and rclpy_to_mrt at most 2x rospy_to_rospy's.
Results: benchmarks/results/services.json and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PEER1 = str(ROOT / "tests" / "peers" / "ros1_service_peer.py")
PEER2 = str(ROOT / "tests" / "peers" / "ros2_service_peer.py")
STOCK_PYTHON = "/usr/bin/python3"
MRT_PYTHON = str(ROOT / ".venv" / "bin" / "python")
ROS2_PYTHON = str(ROOT / ".venv-ros2" / "bin" / "python")
RESULTS = HERE / "results"

#: stack -> (server kind, client kind); kinds: rospy, micros_rt, rclpy
STACKS = {
    "rospy_to_rospy": ("rospy", "rospy"),
    "mrt_to_rclpy": ("rclpy", "micros_rt"),
    "rclpy_to_mrt": ("micros_rt", "rclpy"),
    "rclpy_to_rclpy": ("rclpy", "rclpy"),
}
SRV1, SRV2 = "std_srvs/SetBool", "std_srvs/srv/SetBool"


def eth0_tx() -> Optional[int]:
    try:
        return int(Path("/sys/class/net/eth0/statistics/tx_packets").read_text())
    except (OSError, ValueError):
        return None


def load() -> float:
    return os.getloadavg()[0]


def start_master(env: Dict[str, str], logdir: Path) -> "subprocess.Popen[bytes]":
    port = env["ROS_MASTER_URI"].rsplit(":", 1)[1]
    log = open(logdir / "rosmaster.log", "w")
    proc = subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", port], env=env, stdout=log, stderr=log,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    import xmlrpc.client
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]).getSystemState("/bench")
            return proc
        except OSError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("rosmaster did not come up within 20 s")


def server_argv(kind: str, name: str) -> List[str]:
    if kind == "rclpy":
        spec = [{"name": name, "type": SRV2}]
        return [ROS2_PYTHON, PEER2, "serve", "--quiet", "--seconds", "600", "--services", json.dumps(spec)]
    python = MRT_PYTHON if kind == "micros_rt" else STOCK_PYTHON
    spec = [{"name": name, "type": SRV1}]
    return [python, PEER1, "--impl", kind, "serve", "--quiet", "--seconds", "600", "--services", json.dumps(spec)]


def client_argv(kind: str, name: str, calls: int) -> List[str]:
    srv = SRV2 if kind == "rclpy" else SRV1
    timeout = {"timeout": 10.0}
    plan = [{"label": "first", "name": name, "type": srv, "args": {"data": True}, "wait": 30, **timeout},
            {"label": "warm-up", "name": name, "type": srv, "args": {"data": True}, "count": 20, **timeout},
            {"label": "measured", "name": name, "type": srv, "args": {"data": True}, "count": calls, **timeout}]
    if kind == "rclpy":
        return [ROS2_PYTHON, PEER2, "call", "--plan", json.dumps(plan)]
    python = MRT_PYTHON if kind == "micros_rt" else STOCK_PYTHON
    return [python, PEER1, "--impl", kind, "call", "--plan", json.dumps(plan)]


def read_events(proc: "subprocess.Popen[str]", until: str, timeout: float) -> List[Dict[str, Any]]:
    """JSON events from ``proc``'s stdout up to the first of kind ``until``."""
    import select
    assert proc.stdout is not None
    events: List[Dict[str, Any]] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.5)
        if not ready:
            if proc.poll() is not None:
                break
            continue
        line = proc.stdout.readline()
        if not line:
            break
        try:
            event = json.loads(line)
        except ValueError:
            continue
        events.append(event)
        if event.get("event") == until:
            return events
    raise RuntimeError(f"no {until!r} event within {timeout:g} s (events: {events[-3:]})")


def stop(proc: "subprocess.Popen[Any]") -> None:
    if proc.poll() is None:
        proc.send_signal(2)
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run_stack(stack: str, calls: int, env: Dict[str, str], logdir: Path, n: int) -> Dict[str, Any]:
    server_kind, client_kind = STACKS[stack]
    name = f"/bench_{stack}_{n}"
    logs = [open(logdir / f"{stack}_{n}_{side}.log", "w") for side in ("server", "client")]
    server = subprocess.Popen(server_argv(server_kind, name), env=env, stdout=subprocess.PIPE, stderr=logs[0],
                              text=True, start_new_session=True)
    client: Optional["subprocess.Popen[str]"] = None
    try:
        read_events(server, "ready", 60)
        client = subprocess.Popen(client_argv(client_kind, name, calls), env=env, stdout=subprocess.PIPE,
                                  stderr=logs[1], text=True, start_new_session=True)
        events = read_events(client, "done", 120 + calls * 0.1)
        measured = [e for e in events if e.get("event") == "summary" and e.get("label") == "measured"]
        if not measured:
            raise RuntimeError(f"{stack}: no measured summary: {events[-3:]}")
        m = measured[0]
        return {"stack": stack, "server": server_kind, "client": client_kind, "calls": calls, "answered": m["ok"],
                "errors": m["n_errors"], "first_errors": m["errors"], "p50_us": m["p50_us"], "p99_us": m["p99_us"],
                "side": m.get("side")}
    finally:
        if client is not None:
            stop(client)
        stop(server)
        for log in logs:
            log.close()



def bench_env(prefix: str) -> Tuple[Dict[str, str], Path]:
    """The environment every process of a services benchmark runs in, and its log directory: a master on a free
    loopback port, a random DDS domain, loopback-only Cyclone and Fast DDS, nothing of the caller's ROS set-up."""
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    logdir = Path(tempfile.mkdtemp(prefix=prefix))
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "CYCLONEDDS", "FASTRTPS", "FASTDDS", "RMW_", "PYTHONPATH", "AMENT",
                                "MICROS_RT", "VIRTUAL_ENV"))}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_IP="127.0.0.1", ROS_DOMAIN_ID=str(random.randint(1, 200)),
               PYTHONUNBUFFERED="1", ROS_HOME=str(logdir / "roshome"), ROS_LOG_DIR=str(logdir / "roslog"),
               CYCLONEDDS_URI=f"file://{HERE / 'cyclonedds_loopback.xml'}",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(HERE / "fastdds_loopback.xml"),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env, logdir

def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--stacks", default=",".join(STACKS))
    parser.add_argument("--out", default=str(RESULTS / "services"))
    args = parser.parse_args()
    stacks = [s for s in args.stacks.split(",") if s]
    for s in stacks:
        if s not in STACKS:
            raise SystemExit(f"unknown stack {s!r}: one of {', '.join(STACKS)}")

    env, logdir = bench_env("micros_rt_bench_services_")
    tx0, load0 = eth0_tx(), load()
    master = start_master(env, logdir)
    rows: List[Dict[str, Any]] = []
    try:
        for r in range(args.rounds):
            order = stacks if r % 2 == 0 else list(reversed(stacks))
            for stack in order:
                row = run_stack(stack, args.calls, env, logdir, r)
                row["round"] = r
                rows.append(row)
                print(f"round {r} {stack:15s} answered {row['answered']}/{row['calls']}  "
                      f"p50 {row['p50_us']:8.0f} us  p99 {row['p99_us']:8.0f} us", flush=True)
    finally:
        stop(master)
    tx1, load1 = eth0_tx(), load()

    def median(values: List[float]) -> float:
        values = sorted(values)
        return values[len(values) // 2]

    summary: Dict[str, Dict[str, Any]] = {}
    for stack in stacks:
        mine = [row for row in rows if row["stack"] == stack]
        summary[stack] = {"p50_us": median([row["p50_us"] for row in mine]),
                          "p99_us": median([row["p99_us"] for row in mine]),
                          "answered": sum(row["answered"] for row in mine), "calls": sum(row["calls"] for row in mine)}
    ref = summary.get("rospy_to_rospy", {}).get("p50_us")
    for stack, s in summary.items():
        s["p50_vs_rospy"] = (s["p50_us"] / ref) if ref else None
    result = {"date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "calls": args.calls,
              "rounds": args.rounds, "load_before": load0, "load_after": load1,
              "eth0_tx_delta": (tx1 - tx0) if tx0 is not None and tx1 is not None else None,
              "rows": rows, "summary": summary}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [f"# Service calls ({result['date']}, {args.calls} calls x {args.rounds} round(s), loopback, "
             f"load {load0:.2f} -> {load1:.2f}, eth0 packets sent meanwhile: {result['eth0_tx_delta']})", "",
             "| stack | answered | p50 (us) | p99 (us) | p50 / rospy's |", "| --- | --- | --- | --- | --- |"]
    for stack, s in summary.items():
        ratio = "" if s["p50_vs_rospy"] is None else f"{s['p50_vs_rospy']:.2f}"
        lines.append(f"| {stack} | {s['answered']}/{s['calls']} | {s['p50_us']:.0f} | {s['p99_us']:.0f} | {ratio} |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    shutil.rmtree(logdir, ignore_errors=True)
    ok = all(s["answered"] == s["calls"] for s in summary.values()) and all(
        (s["p50_vs_rospy"] or 0) <= 2.0 for k, s in summary.items() if k in ("mrt_to_rclpy", "rclpy_to_mrt"))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
