"""Start-up of a node that offers a service and publishes and subscribes in its first second, started again and
again in one graph: does DDS ever go missing for the process? (issue 41: 4 of 8 starts with ``CYCLONEDDS_URI``
set, 3 of 14 without, lost DDS to cyclonedds's cyclic imports racing between threads.)

    .venv/bin/python benchmarks/startup_dds.py [--starts 100] [--domain 231] [--out benchmarks/results/startup_dds.json]

Each start is a fresh ``.venv/bin/python`` process under the defaults (no MICROS_RT_* setting), run twice per
round: with ``CYCLONEDDS_URI`` naming the loopback configuration and with it unset (micros_rt's own rule). A start
counts as failed when its participant did not start, or its service is not served to ROS 2 (its helper needs the
DDS type mapping), or the process did not finish cleanly. Its own rosmaster and DDS domain; loopback only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, List

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import harness  # noqa: E402

NODE = r'''
import json, time
import micros_rt
from std_msgs.msg import String
from std_srvs.srv import Trigger, TriggerResponse
micros_rt.init_node("startnode", anonymous=True)
nh = micros_rt.NodeHandle()
srv = nh.advertise_service("~trigger", Trigger, lambda req: TriggerResponse(success=True, message="ok"))
pub = nh.advertise("start_topic", String, 10)
sub = nh.subscribe("start_topic", String, lambda m: None, 10)
t0 = time.time()
while time.time() - t0 < 1.0:
    pub.publish(String(data="x"))
    time.sleep(0.05)
from micros_rt.transports.dds import participant
print(json.dumps({"failed": participant._failed, "ros2_error": srv.ros2_error}), flush=True)
micros_rt.shutdown()
'''


def one_start(env: Dict[str, str]) -> Dict[str, Any]:
    t0 = time.monotonic()
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", NODE], env=env, cwd=str(ROOT), capture_output=True, text=True,
                        timeout=120)
    lines = [line for line in cp.stdout.splitlines() if line.startswith("{")]
    result: Dict[str, Any] = json.loads(lines[-1]) if lines else {"failed": f"no result (exit {cp.returncode})"}
    result["ok"] = cp.returncode == 0 and result.get("failed") is None and result.get("ros2_error") is None
    result["seconds"] = time.monotonic() - t0
    if not result["ok"]:
        result["stderr"] = cp.stderr[-600:]
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--starts", type=int, default=100, help="starts per environment")
    ap.add_argument("--domain", type=int, default=231)
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    master = harness.RosMaster()
    master.start()
    try:
        base = {k: v for k, v in master.env.items() if not k.startswith("MICROS_RT_")}
        base.update(harness.dds_env(args.domain))
        envs = {"CYCLONEDDS_URI set": base, "CYCLONEDDS_URI unset": {k: v for k, v in base.items()
                                                                     if k != "CYCLONEDDS_URI"}}
        results: Dict[str, List[Dict[str, Any]]] = {name: [] for name in envs}
        for i in range(args.starts):
            for name, env in envs.items():
                r = one_start(env)
                results[name].append(r)
                if not r["ok"]:
                    print(f"start {i} ({name}): {json.dumps(r)}", flush=True)
        summary = {name: {"starts": len(rs), "dds_unavailable": sum(1 for r in rs if r.get("failed")),
                          "not_served_to_ros2": sum(1 for r in rs if r.get("ros2_error")),
                          "failed": sum(1 for r in rs if not r["ok"]),
                          "median_s": sorted(r["seconds"] for r in rs)[len(rs) // 2]}
                   for name, rs in results.items()}
        print(json.dumps(summary, indent=1))
        if args.out:
            Path(args.out).write_text(json.dumps({"summary": summary, "results": results}, indent=1))
        return 0 if all(s["failed"] == 0 for s in summary.values()) else 1
    finally:
        master.cleanup()


if __name__ == "__main__":
    sys.exit(main())
