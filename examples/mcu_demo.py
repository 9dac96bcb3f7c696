#!/usr/bin/env python3
"""The microcontroller demo: a C "board" (tests/peers/mcu_standin.c, built here with gcc against Debian's
libmsgpack-dev), ``micros-rt mcu-bridge --config examples/mcu_bridge.yaml`` and a micros_rt node
(examples/mcu_robot.py), all on loopback. Starts a rosmaster when none is reachable, runs a few seconds,
prints what each side saw and the bridge's counters, and stops everything it started.

    .venv/bin/python examples/mcu_demo.py
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, Iterator, List

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from demo import free_port, master_reachable, stop  # noqa: E402  (the QoS demo's helpers)

STANDIN = HERE.parent / "tests" / "peers" / "mcu_standin.c"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=6.0, help="seconds the robot node runs")
    args = ap.parse_args()
    env: Dict[str, str] = dict(os.environ, ROS_IP=os.environ.get("ROS_IP", "127.0.0.1"), PYTHONUNBUFFERED="1")
    env.setdefault("ROS_MASTER_URI", "http://127.0.0.1:11311")
    started: List["subprocess.Popen[Any]"] = []
    with tempfile.TemporaryDirectory(prefix="mcu_demo_") as tmp:
        board_binary = Path(tmp) / "mcu_standin"
        subprocess.run(["gcc", "-O2", "-o", str(board_binary), str(STANDIN), "-lmsgpackc", "-lm"], check=True)
        try:
            if not master_reachable(env["ROS_MASTER_URI"]):
                env["ROS_MASTER_URI"] = f"http://127.0.0.1:{free_port()}"
                print(f"mcu demo: starting rosmaster at {env['ROS_MASTER_URI']}", flush=True)
                started.append(subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p",
                                                 env["ROS_MASTER_URI"].rsplit(":", 1)[1]], env=env,
                                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
                deadline = time.monotonic() + 20
                while not master_reachable(env["ROS_MASTER_URI"]) and time.monotonic() < deadline:
                    time.sleep(0.1)
            bridge = subprocess.Popen([sys.executable, "-m", "micros_rt.bridges.mcu", "--config",
                                       str(HERE / "mcu_bridge.yaml"), "--json"], env=env, stdout=subprocess.PIPE)
            started.append(bridge)
            assert bridge.stdout is not None
            bridge.stdout.readline()  # {"event": "ready", ...}: the bridge's ROS side is up
            robot = subprocess.Popen([sys.executable, str(HERE / "mcu_robot.py"), "--duration", str(args.duration)],
                                     env=env)
            started.append(robot)
            board = subprocess.Popen([str(board_binary), "--rate", "100", "--call", "set_mode", "--call-arg", "true",
                                      "--call-after", "3", "--pause-after", "250", "--pause", "1.5",
                                      "--duration", str(args.duration + 2)], stdout=subprocess.PIPE, text=True)
            started.append(board)
            out, _ = board.communicate(timeout=args.duration + 30)
            robot.wait(30)
            commands = 0
            for event in _json_lines(out, "board"):
                if event["event"] == "recv":
                    commands += 1
                    if commands == 1:
                        print(f"board: first command {event['name']} {event['fields']} (IP TOS {event['tos']})")
                elif event["event"] != "ready":
                    print(f"board: {json.dumps(event)}")
            print(f"board: received {commands} commands", flush=True)
            stop(bridge)
            last = list(_json_lines(bridge.stdout.read().decode(), "bridge"))
            stats = [e for e in last if e.get("event") == "stats"]
            if stats:
                print(f"bridge counters: {json.dumps({k: v for k, v in stats[-1].items() if k != 'event'})}")
            print("mcu demo: done", flush=True)
            return 0
        except KeyboardInterrupt:
            return 130
        finally:
            for p in reversed(started):
                stop(p)


def _json_lines(text: str, who: str) -> Iterator[Dict[str, Any]]:
    """The JSON events in ``text``; any other line (a library's print to stdout) is shown as it is, not fatal
    (one run ended in JSONDecodeError on such a line)."""
    for line in text.splitlines():
        try:
            event = json.loads(line)
        except ValueError:
            if line.strip():
                print(f"{who}: {line}")
            continue
        if isinstance(event, dict) and "event" in event:
            yield event


if __name__ == "__main__":
    sys.exit(main())
