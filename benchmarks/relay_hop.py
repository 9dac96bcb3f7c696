"""What ``micros-rt relay`` costs on its own host (issue 21, deliverable 2): stock rospy publisher and subscriber
on one host's loopback, either linked directly (one rosmaster) or through two relays (two rosmasters, robot A's
relay exporting, robot B's importing, DDS on loopback between them), in the same run, alternating.

    .venv/bin/python benchmarks/relay_hop.py                       # both scenarios, 8 s, 3 rounds
    .venv/bin/python benchmarks/relay_hop.py --scenarios small --rounds 1

Scenarios (tests/peers/mrt_link.py, one publisher process with two threads, one subscriber process):
  small  /control geometry_msgs/PointStamped at 100 Hz (stamp = wall clock), /image 4x4 at 1 Hz
  1080p  /control at 100 Hz and /image sensor_msgs/Image 1920x1080 rgb8 at 30 Hz (186 MB/s)

Stacks (``--stacks``):
  direct          stock publisher -> stock subscriber, one master
  relay           stock publisher -> relay A (TCPROS) -> relay B (DDS) -> stock subscriber (TCPROS)
  mrt_renamed     the same with a micros_rt subscriber, the import renamed (``as: /control``): it opens a reader
                  on the outside topic and reads relay A's DDS writer straight (until renamed imports were
                  served straight it read relay B's own writer, a hop through relay B's process: the
                  ``mrt_through`` rows of results/relay_hop.md)
  mrt_straight    a micros_rt subscriber of the import under its outside name (/robot_a/control): it reads relay
                  A's DDS writer straight, relay B only answers its negotiation

"Per hop" is the difference of the medians of direct and relay divided by the two links the relays add. Robot
A's relay exports the camera with a history of 6 (RELAY_EXPORT says why).
Results: benchmarks/results/relay_hop.json and .md.
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from constrained_link import PEER, RELAY_IMPORT, markdown_table, outcome, stop_relays  # noqa: E402
from run import child_env, eth0_tx, start_master  # noqa: E402

ROOT = HERE.parent
STOCK_PYTHON = "/usr/bin/python3"
MRT_PYTHON = str(ROOT / ".venv" / "bin" / "python")
CLI = str(ROOT / ".venv" / "bin" / "micros-rt")
#: Robot A's relay. The camera's history is 6 frames: a reliable DDS writer's history is what a retransmission
#: is served from, and on this host (net.core.rmem_max 4 MB, below one 6.2 MB frame) the receiving socket
#: overflows now and then; with a history of 2 the frame asked for again had been replaced by two newer ones
#: by the time the request came, and 1-2 of 240 frames never arrived (Cyclone reports no loss for that).
RELAY_EXPORT = ("graph: robot_a\nexport:\n  /control: {transport_priority: HIGH, queue_size: 100}\n"
                "  /image: {transport_priority: LOW, queue_size: 6}\n")
#: Robot B's relay for a micros_rt subscriber of the outside names (mrt_straight)
RELAY_IMPORT_OUTSIDE = ("graph: robot_b\nimport:\n  /robot_a/control: {queue_size: 100}\n"
                        "  /robot_a/image: {queue_size: 2}\n")
STACKS = ("direct", "relay", "mrt_renamed", "mrt_straight")
SCENARIOS = {
    "small": ["--control-rate", "100", "--image-rate", "1", "--width", "4", "--height", "4"],
    "1080p": ["--control-rate", "100", "--image-rate", "30", "--width", "1920", "--height", "1080"],
}


def popen(argv: List[str], env: Dict[str, str], log: Path) -> "subprocess.Popen[str]":
    return subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=open(log, "w"), text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def one_run(stack: str, scenario: str, seconds: float, logdir: Path, profile: bool = False) -> Dict[str, Any]:
    domain = random.randrange(100, 200)
    relayed = stack != "direct"
    masters = [start_master(logdir) for _ in range(2 if relayed else 1)]
    envs = [child_env("micros_rt", uri, domain) for _, uri in masters]
    relays: List["subprocess.Popen[str]"] = []
    procs: List["subprocess.Popen[str]"] = []
    try:
        if relayed:
            imports = RELAY_IMPORT_OUTSIDE if stack == "mrt_straight" else RELAY_IMPORT
            for i, text in enumerate((RELAY_EXPORT, imports)):
                config = logdir / f"relay{i}.yaml"
                config.write_text(text)
                relays.append(popen([CLI, "relay", "--config", str(config), "--poll-period", "0.3", "--json",
                                     "--stats-period", "2"], envs[i], logdir / f"relay{i}.log"))
        peer = [STOCK_PYTHON, str(PEER)]
        if stack.startswith("mrt_"):
            names = (["--control-topic", "/robot_a/control", "--image-topic", "/robot_a/image"]
                     if stack == "mrt_straight" else [])
            sub_argv = [MRT_PYTHON, str(PEER), "sub", *names]
        else:
            sub_argv = [*peer, "sub", "--stock"]
        sub = popen([*sub_argv, "--seconds", str(seconds + 60), *SCENARIOS[scenario]], envs[-1], logdir / "sub.log")
        delay = ["--start-delay", "6"] if relayed else ["--start-delay", "1"]
        pub = popen([*peer, "pub", "--stock", "--seconds", str(seconds), *delay, *SCENARIOS[scenario]], envs[0],
                    logdir / "pub.log")
        procs = [sub, pub]
        if profile and relays:  # py-spy on both relays while the publisher sends (its start delay first)
            spy = str(ROOT / ".venv" / "bin" / "py-spy")
            procs += [subprocess.Popen(["sh", "-c", f"sleep 7; exec {spy} record -p {relay.pid} -d {seconds - 2:.0f} "
                                        f"-r 200 -f raw --threads -o {logdir}/relay{i}.spy"],
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                      for i, relay in enumerate(relays)]
        published, summary = outcome(pub, sub, seconds)
    finally:
        relay_stats = stop_relays(relays)
        for proc in procs:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
        for master, _ in masters:
            master.terminate()
            master.wait(10)
    if published is None or summary is None:
        return {"error": f"no {'published' if published is None else 'summary'} event (logs in {logdir})"}
    return {"control_published": published["control"], "control_delivered": summary["control"],
            "control_p50_ms": summary["p50_ms"], "control_p99_ms": summary["p99_ms"],
            "images_published": published["image"], "images_delivered": summary["image"],
            "image_p50_ms": summary["image_p50_ms"], **({"relay_statistics": relay_stats} if relays else {})}


def median(values: List[float]) -> Optional[float]:
    values = sorted(v for v in values if v is not None)
    return values[len(values) // 2] if values else None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scenarios", default="small,1080p", help="small, 1080p; comma-separated")
    ap.add_argument("--stacks", default=",".join(STACKS), help=f"{', '.join(STACKS)}; comma-separated")
    ap.add_argument("--out", default=str(HERE / "results"))
    ap.add_argument("--profile", action="store_true", help="py-spy the relays (raw stacks in the run's log dir)")
    args = ap.parse_args()
    tx_before = eth0_tx()
    results: Dict[str, Dict[str, List[Dict[str, Any]]]] = {}
    logroot = Path(tempfile.mkdtemp(prefix="micros_rt_relay_hop_"))
    for r in range(args.rounds):
        for scenario in args.scenarios.split(","):
            stacks = args.stacks.split(",")
            stacks = stacks if r % 2 == 0 else stacks[::-1]
            for stack in stacks:
                print(f"round {r + 1}/{args.rounds}: {scenario}, {stack} ...", flush=True)
                logdir = logroot / f"{r}_{scenario}_{stack}"
                logdir.mkdir()
                results.setdefault(scenario, {}).setdefault(stack, []).append(
                    one_run(stack, scenario, args.seconds, logdir, args.profile))
    tx_after = eth0_tx()
    lines = markdown_table(
        ["scenario", "stack", "control delivered / published", "control p50 ms", "p99 ms",
         "images delivered / published", "image p50 ms"], results,
        lambda run: [f"{run['control_delivered']:,} / {run['control_published']:,}", f"{run['control_p50_ms']:.2f}",
                     f"{run['control_p99_ms']:.2f}", f"{run['images_delivered']} / {run['images_published']}",
                     f"{run['image_p50_ms']:.1f}"])
    summary: Dict[str, Any] = {}
    for scenario, stacks in results.items():
        medians = {stack: median([run.get("control_p50_ms") for run in runs]) for stack, runs in stacks.items()}
        image_medians = {stack: median([run.get("image_p50_ms") for run in runs]) for stack, runs in stacks.items()}
        summary[scenario] = {"control_p50_ms": medians, "image_p50_ms": image_medians}
        if medians.get("direct") is not None and medians.get("relay") is not None:
            summary[scenario].update({
                "added_per_hop_ms": round((medians["relay"] - medians["direct"]) / 2, 3),
                "image_added_per_hop_ms": (None if None in (image_medians.get("relay"), image_medians.get("direct"))
                                           else round((image_medians["relay"] - image_medians["direct"]) / 2, 3))})
    for scenario, s in summary.items():
        medians = s["control_p50_ms"]
        lines.append(f"\n{scenario}: control p50 " + ", ".join(
            f"{stack} {v:.2f} ms" for stack, v in medians.items() if v is not None)
            + (f"; {s['added_per_hop_ms']:.2f} ms per added hop" if "added_per_hop_ms" in s else "")
            + (f"; image p50 {s['image_added_per_hop_ms']:.1f} ms per added hop"
               if s.get("image_added_per_hop_ms") is not None else ""))
    report = {"seconds": args.seconds, "rounds": args.rounds,
              "command": " ".join([".venv/bin/python", "benchmarks/relay_hop.py", *sys.argv[1:]]),
              "eth0_tx_packets_during_run": None if None in (tx_before, tx_after) else tx_after - tx_before,
              "summary": summary, "runs": results, "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "relay_hop.json").write_text(json.dumps(report, indent=1))
    (out / "relay_hop.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"eth0 tx packets during the run: {report['eth0_tx_packets_during_run']} (the machine is shared)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
