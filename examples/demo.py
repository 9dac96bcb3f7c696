#!/usr/bin/env python3
"""The QoS talker/listener demo: starts a rosmaster when none is reachable, runs
examples/talker.py and examples/listener.py for a few seconds, prints what the
listener hears, and stops everything it started.

Everything stays on loopback: ROS_IP defaults to 127.0.0.1, which makes
micros_rt bind Cyclone DDS to ``lo`` without multicast.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from pathlib import Path
from typing import Dict, List, Optional

HERE = Path(__file__).resolve().parent


def master_reachable(uri: str) -> bool:
    try:
        code, _msg, _pid = xmlrpc.client.ServerProxy(uri).getPid("/demo")
        return bool(code == 1)
    except (OSError, xmlrpc.client.Error):
        return False


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def stop(proc: "subprocess.Popen[bytes]", timeout: float = 5.0) -> None:
    if proc.poll() is not None:
        return
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        proc.send_signal(sig)
        try:
            proc.wait(timeout)
            return
        except subprocess.TimeoutExpired:
            continue


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=6.0, help="seconds the talker runs")
    args = ap.parse_args()

    env: Dict[str, str] = dict(os.environ)
    if not env.get("ROS_IP") and not env.get("ROS_HOSTNAME"):
        env["ROS_IP"] = "127.0.0.1"
    env.setdefault("ROS_MASTER_URI", "http://127.0.0.1:11311")
    env["PYTHONUNBUFFERED"] = "1"
    started: List["subprocess.Popen[bytes]"] = []
    master: Optional["subprocess.Popen[bytes]"] = None
    try:
        if not master_reachable(env["ROS_MASTER_URI"]):
            port = free_port()
            env["ROS_MASTER_URI"] = f"http://127.0.0.1:{port}"
            print(f"demo: no ROS master reachable, starting rosmaster on port {port}", flush=True)
            master = subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            started.append(master)
            deadline = time.monotonic() + 20
            while not master_reachable(env["ROS_MASTER_URI"]):
                if time.monotonic() > deadline or master.poll() is not None:
                    print("demo: rosmaster did not start", file=sys.stderr)
                    return 1
                time.sleep(0.1)
        else:
            print(f"demo: using the ROS master at {env['ROS_MASTER_URI']}", flush=True)
        listener = subprocess.Popen([sys.executable, str(HERE / "listener.py"), "--duration",
                                     str(args.duration + 3)], env=env)
        started.append(listener)
        time.sleep(1.0)  # let the listener register first, so it hears the first seconds
        talker = subprocess.Popen([sys.executable, str(HERE / "talker.py"), "--duration", str(args.duration)],
                                  env=env)
        started.append(talker)
        talker.wait(args.duration + 30)
        listener.wait(30)
        ok = talker.returncode == 0 and listener.returncode == 0
        print("demo: done" if ok else "demo: a node failed", flush=True)
        return 0 if ok else 1
    except KeyboardInterrupt:
        return 130
    finally:
        for p in reversed(started):
            stop(p)


if __name__ == "__main__":
    sys.exit(main())
