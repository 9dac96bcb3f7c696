"""What offering one service costs a node when no ROS 2 node is on its DDS domain: the time from the process's
start to its service being offered, and the PSS of the process with its children (the ROS 2 helper is one).
And what ``--host N`` processes offering a service each cost with their ROS 2 side up (as with a ROS 2 node on the
domain): the ROS 2 helper processes of the host for that domain, their PSS and Fast DDS participants.

    .venv/bin/python benchmarks/service_cost.py [--rounds 3] [--host 10] [--domain 232] \
        [--out benchmarks/results/service_cost.json]

Two cases per round, each a fresh process (tests/peers/ros1_service_peer.py, one std_srvs/Trigger): the defaults
(ROS 2 visibility ``auto``: no rclpy helper until a ROS 2 node comes) and ``MICROS_RT_ROS2=on`` (the helper starts
with the service, as every mode did before issue 42's second session). Its own rosmaster and DDS domain; loopback.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import harness  # noqa: E402


def pss_kb(pids: List[int]) -> int:
    total = 0
    for p in pids:
        try:
            total += sum(int(line.split()[1]) for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines()
                         if line.startswith("Pss:"))
        except OSError:
            pass
    return total


def tree_pss_kb(pid: int) -> Tuple[int, int]:
    """PSS of ``pid`` and its children (kB), and how many processes that is."""
    pids = [pid]
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            pids += [int(c) for c in Path(f"/proc/{pid}/task/{task}/children").read_text().split()]
        except OSError:
            pass
    return pss_kb(pids), len(pids)


def one(master: harness.RosMaster, domain: int, on: bool, settle: float) -> Dict[str, Any]:
    env = dict(master.env, ROS_DOMAIN_ID=str(domain))
    if on:
        env["MICROS_RT_ROS2"] = "on"
    t0 = time.monotonic()
    peer = harness.Peer([harness.MICROS_RT_PYTHON, str(ROOT / "tests/peers/ros1_service_peer.py"), "--impl",
                         "micros_rt", "serve", "--services",
                         json.dumps([{"name": "/cost/trigger", "type": "std_srvs/Trigger"}]), "--seconds", "60"],
                        env=env, name="on" if on else "auto")
    try:
        ready = peer.wait_for("ready", 60)
        offered = time.monotonic() - t0
        time.sleep(settle)  # the helper (if any) up and idle
        pss, processes = tree_pss_kb(peer.proc.pid)
    finally:
        peer.stop()
    return {"offered_s": round(offered, 3), "pss_mb": round(pss / 1024, 1), "processes": processes,
            "ros2": ready.get("ros2"), "waiting": ready.get("waiting")}


def helpers_on(domain: int) -> List[int]:
    """The ROS 2 helper processes of this user whose environment has ``ROS_DOMAIN_ID=domain``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if "ros2_helper.py" not in (entry / "cmdline").read_text() or entry.stat().st_uid != os.getuid():
                continue
            env = (entry / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if f"ROS_DOMAIN_ID={domain}".encode() in env:
            found.append(int(entry.name))
    return found


def host(master: harness.RosMaster, domain: int, n: int, settle: float) -> Dict[str, Any]:
    """``n`` processes offering a service each, their ROS 2 side up at once (``MICROS_RT_ROS2=on``, as when a ROS 2
    node is on the domain): the host's helpers for the domain, their PSS, and the servers' own."""
    env = dict(master.env, ROS_DOMAIN_ID=str(domain), MICROS_RT_ROS2="on")
    t0 = time.monotonic()
    peers = [harness.Peer([harness.MICROS_RT_PYTHON, str(ROOT / "tests/peers/ros1_service_peer.py"), "--impl",
                           "micros_rt", "serve", "--services",
                           json.dumps([{"name": f"/cost/host_{i}", "type": "std_srvs/Trigger"}]), "--seconds", "120"],
                          env=env, name=f"host_{i}") for i in range(n)]
    try:
        for peer in peers:
            peer.wait_for("ready", 120)
        offered = time.monotonic() - t0
        time.sleep(settle)
        helpers = helpers_on(domain)
        result = {"processes": n, "all_offered_s": round(offered, 2), "helpers": len(helpers),
                  "helpers_pss_mb": round(pss_kb(helpers) / 1024, 1),
                  "servers_pss_mb": round(pss_kb([p.proc.pid for p in peers]) / 1024, 1)}
    finally:
        for peer in peers:
            peer.stop()
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--domain", type=int, default=232)
    ap.add_argument("--settle", type=float, default=5.0)
    ap.add_argument("--host", type=int, default=0, help="also N processes with a service each, ROS 2 side up")
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/service_cost.json"))
    args = ap.parse_args()
    master = harness.RosMaster(domain_id=args.domain)
    master.start()
    runs: Dict[str, List[Dict[str, Any]]] = {"auto": [], "on": []}
    hosts: List[Dict[str, Any]] = []
    try:
        for _ in range(args.rounds):
            for case in ("auto", "on"):
                runs[case].append(one(master, args.domain, case == "on", args.settle))
            if args.host:
                hosts.append(host(master, args.domain, args.host, args.settle))
    finally:
        master.cleanup()
    summary = {case: {"offered_s_median": statistics.median(r["offered_s"] for r in rs),
                      "pss_mb_median": statistics.median(r["pss_mb"] for r in rs),
                      "processes": sorted({r["processes"] for r in rs})} for case, rs in runs.items()}
    result = {"command": " ".join(["benchmarks/service_cost.py", *sys.argv[1:]]),
              "time": time.strftime("%Y-%m-%d %H:%M:%S"), "load_average": os.getloadavg(), "runs": runs,
              "summary": summary, "host": hosts}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    for case, s in summary.items():
        print(f"{case:5s} offered after {s['offered_s_median']:.2f} s, PSS {s['pss_mb_median']:.1f} MB, "
              f"processes {s['processes']}")
    for h in hosts:
        print(f"host: {h['processes']} processes with a service each, ROS 2 side up: {h['helpers']} ROS 2 helper "
              f"process(es), {h['helpers_pss_mb']:.1f} MB PSS (the servers {h['servers_pss_mb']:.1f} MB), all offered "
              f"after {h['all_offered_s']:.1f} s")


if __name__ == "__main__":
    main()
