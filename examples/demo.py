#!/usr/bin/env python3
"""The QoS talker/listener demo: uses the ROS master ROS_MASTER_URI names when it answers, else starts one (on
that URI's port when it names this host, on a free port without ROS_MASTER_URI) and says which; runs
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
import urllib.parse
import xmlrpc.client
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

HERE = Path(__file__).resolve().parent


def master_reachable(uri: str, timeout: float = 3.0) -> bool:
    """Whether a ROS master answers at ``uri`` (its ``getPid``), within ``timeout`` seconds."""
    old = socket.getdefaulttimeout()
    socket.setdefaulttimeout(timeout)
    try:
        code, _msg, _pid = xmlrpc.client.ServerProxy(uri).getPid("/demo")
        return bool(code == 1)
    except (OSError, xmlrpc.client.Error):
        return False
    finally:
        socket.setdefaulttimeout(old)


def master_plan(uri: Optional[str], reachable: Callable[[str], bool]) -> Tuple[str, Optional[int], str]:
    """Which master the demo uses: (its URI, the port of a rosmaster to start there or None, what to say).

    The master ``ROS_MASTER_URI`` names when it answers; else, when it names this host, a rosmaster on that very
    port (so other terminals with the same ROS_MASTER_URI reach it); without ROS_MASTER_URI, the default master
    (port 11311) or one on a free port. A named master on another host that does not answer is an error (port 0).

    >>> master_plan("http://127.0.0.1:11311/", lambda u: True)[1:]
    (None, 'using the ROS master at http://127.0.0.1:11311/ (ROS_MASTER_URI)')
    >>> master_plan("http://localhost:12000", lambda u: False)
    ('http://localhost:12000', 12000, 'no ROS master answers at http://localhost:12000 (ROS_MASTER_URI): starting rosmaster there, on port 12000; it stops when the demo ends')
    """
    if uri:
        if reachable(uri):
            return uri, None, f"using the ROS master at {uri} (ROS_MASTER_URI)"
        parts = urllib.parse.urlparse(uri)
        if parts.hostname in ("localhost", "127.0.0.1", socket.gethostname()) and parts.port:
            return uri, parts.port, (f"no ROS master answers at {uri} (ROS_MASTER_URI): starting rosmaster there, on "
                                     f"port {parts.port}; it stops when the demo ends")
        return uri, 0, (f"no ROS master answers at {uri} (ROS_MASTER_URI), and it is not on this host: start it, or "
                        f"unset ROS_MASTER_URI to let the demo start one")
    default = "http://127.0.0.1:11311"
    if reachable(default):
        return default, None, f"using the ROS master at {default} (ROS_MASTER_URI is not set: the default)"
    port = free_port()
    return (f"http://127.0.0.1:{port}", port, f"no ROS master answers at {default} and ROS_MASTER_URI is not set: "
            f"starting rosmaster on port {port} (ROS_MASTER_URI=http://127.0.0.1:{port}); it stops when the demo "
            f"ends")


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
    uri, port, said = master_plan(env.get("ROS_MASTER_URI", "").strip() or None, master_reachable)
    print(f"demo: {said}", flush=True)
    if port == 0:
        return 1
    env["ROS_MASTER_URI"] = uri
    env["PYTHONUNBUFFERED"] = "1"
    started: List["subprocess.Popen[bytes]"] = []
    try:
        if port is not None:
            master = subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            started.append(master)
            deadline = time.monotonic() + 20
            while not master_reachable(uri):
                if time.monotonic() > deadline or master.poll() is not None:
                    print(f"demo: rosmaster did not start on port {port} (is the port taken?)", file=sys.stderr)
                    return 1
                time.sleep(0.1)
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
