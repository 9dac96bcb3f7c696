"""Shared memory under faults (issue 46): the long measurements behind tests/integration/test_shm_faults.py.

    .venv/bin/python benchmarks/shm_faults.py                    # every part, 50 SIGINT runs
    .venv/bin/python benchmarks/shm_faults.py --parts sigint --runs 10

Parts (real processes: a rosmaster of its own, micros_rt nodes from tests/peers on shared memory, this
machine's loopback only):
  sigint  (and sigint_tcp, sigint_dds: the listener's TransportHints choose that transport)
          a micros_rt talker publishing std_msgs/String as fast as it can (queue_size=None) to a micros_rt
          listener over SHM, sent SIGINT 0.2-1.0 s into its loop, ``--runs`` times: how long each took to end
  forged  1,000 requestTopic calls with well-formed SHM offers from callers that are not nodes, to a lossless
          publisher at 100 Hz: its longest publish(), RSS and /dev/shm files before and after, then a real
          subscriber, then SIGINT
  victim  one forged requestTopic naming a real subscriber (pid 0): whether that subscriber keeps its link
  fill    a private mount namespace whose /dev/shm is a small tmpfs (80 and 160 MiB), a lossless 1 MiB 20 Hz
          stream to a slow subscriber, dd filling /dev/shm after 15 messages: exit code, messages lost, words
Results: benchmarks/results/shm_faults.json and .md.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import xmlrpc.client
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from run import child_env, start_master  # noqa: E402

PY = str(ROOT / ".venv" / "bin" / "python")
FAULTS = str(ROOT / "tests" / "peers" / "mrt_shm_faults.py")
SEQ = str(ROOT / "tests" / "peers" / "mrt_seq.py")
RESULTS = HERE / "results"


class Peer:
    """A child process printing one JSON event per line; its stderr kept."""

    def __init__(self, argv: List[str], env: Dict[str, str]) -> None:
        self.proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     stdin=subprocess.DEVNULL)
        self.events: List[Dict[str, Any]] = []
        self.stderr: List[str] = []
        self._cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=lambda: self.stderr.extend(iter(self.proc.stderr.readline, "")),  # type: ignore
                         daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            with self._cond:
                self.events.append(event)
                self._cond.notify_all()

    def wait_for(self, pred: Callable[[Dict[str, Any]], bool], timeout: float = 60.0) -> Dict[str, Any]:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for e in self.events:
                    if pred(e):
                        return e
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    raise RuntimeError(f"no such event within {timeout} s: {''.join(self.stderr[-20:])}")
                self._cond.wait(min(left, 0.2))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def event(kind: str) -> Callable[[Dict[str, Any]], bool]:
    return lambda e: e.get("event") == kind


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024


def sigint(env: Dict[str, str], runs: int, hints: str = "") -> Dict[str, Any]:
    listener = Peer([PY, FAULTS, "count", "--topic", "/bench/tight", "--hints", hints, "--duration", "3600"], env)
    listener.wait_for(event("ready"))
    took: List[float] = []
    codes: List[Optional[int]] = []
    for run in range(runs):
        talker = Peer([PY, FAULTS, "flood", "--topic", "/bench/tight"], env)
        talker.wait_for(event("flooding"))
        time.sleep(random.uniform(0.2, 1.0))
        t0 = time.monotonic()
        talker.proc.send_signal(signal.SIGINT)
        try:
            talker.proc.wait(10)
            took.append(time.monotonic() - t0)
        except subprocess.TimeoutExpired:
            took.append(float("inf"))
            talker.proc.kill()
            talker.proc.wait()
        codes.append(talker.proc.returncode)
        print(f"sigint ({hints or 'default'}) run {run + 1}/{runs}: ended {took[-1]:.2f} s after SIGINT, exit {codes[-1]}", flush=True)
    listener.stop()
    transports = [e["transports"] for e in listener.events if e.get("event") == "count" and e["transports"]]
    return {"link": transports[-1] if transports else None, "runs": runs, "still_running_after_2s": sum(t >= 2.0 for t in took), "median_s": statistics.median(took),
            "max_s": max(took), "nonzero_exits": sum(c != 0 for c in codes)}


def forged(env: Dict[str, str], master: str) -> Dict[str, Any]:
    from micros_rt.transports.shm.offer import ShmOffer
    from micros_rt.qos import SubscribeQoSOptions
    from micros_rt.transports.shm.host import host_identity
    from std_msgs.msg import String

    talker = Peer([PY, FAULTS, "flood", "--topic", "/bench/forged", "--node-name", "bench_forged_pub", "--rate",
                   "100", "--no-wait", "--report", "100"], env)
    talker.wait_for(event("advertised"))
    time.sleep(1.0)
    uri = xmlrpc.client.ServerProxy(master).lookupNode("/bench", "/bench_forged_pub")[2]
    offer = ShmOffer(host=host_identity(), md5=String._md5sum, type_name=String._type, qos=SubscribeQoSOptions(),
                     pid=os.getpid()).to_xmlrpc()
    rss0, files0 = rss_mb(talker.proc.pid), len(os.listdir("/dev/shm"))

    def forge(i: int) -> Any:
        return xmlrpc.client.ServerProxy(uri).requestTopic(f"/forged_{i}", "/bench/forged", [offer])

    t0 = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(4) as pool:
        answers = list(pool.map(forge, range(1000)))
    forging = time.monotonic() - t0
    time.sleep(1.0)
    rss1, files1 = rss_mb(talker.proc.pid), len(os.listdir("/dev/shm"))
    listener = Peer([PY, FAULTS, "count", "--topic", "/bench/forged", "--duration", "600"], env)
    linked = listener.wait_for(
        lambda e: e.get("event") == "count" and e["transports"] == ["SHM"] and e["received"] > 50)
    n = len([e for e in talker.events if e.get("event") == "progress"])
    talker.wait_for(lambda e: e.get("event") == "progress" and talker.events.index(e) >= n)
    t0 = time.monotonic()
    talker.proc.send_signal(signal.SIGINT)
    try:
        talker.proc.wait(60)
    except subprocess.TimeoutExpired:
        talker.proc.kill()
    shutdown = time.monotonic() - t0
    stopped = talker.wait_for(event("stopped"), 5)
    listener.stop()
    return {"accepted": sum(a[0] == 1 for a in answers), "forging_s": forging, "rss_before_mb": rss0,
            "rss_after_mb": rss1, "dev_shm_files_before": files0, "dev_shm_files_after": files1,
            "real_subscriber_transports": linked["transports"], "longest_publish_s": stopped["longest_publish"],
            "shutdown_s": shutdown,
            "words": next((line.strip()[:220] for line in talker.stderr if "not a node registered" in line), "")}


def victim(env: Dict[str, str], master: str) -> Dict[str, Any]:
    from micros_rt.transports.shm.offer import ShmOffer
    from micros_rt.qos import SubscribeQoSOptions
    from micros_rt.transports.shm.host import host_identity
    from std_msgs.msg import String

    listener = Peer([PY, FAULTS, "count", "--topic", "/bench/victim", "--node-name", "bench_victim", "--duration",
                     "600"], env)
    listener.wait_for(event("ready"))
    talker = Peer([PY, FAULTS, "flood", "--topic", "/bench/victim", "--node-name", "bench_victim_pub", "--rate", "100",
                   "--flooding-after", "50"], env)
    talker.wait_for(event("flooding"))
    before = listener.wait_for(lambda e: e.get("event") == "count" and e["transports"] == ["SHM"])
    uri = xmlrpc.client.ServerProxy(master).lookupNode("/bench", "/bench_victim_pub")[2]
    offer = ShmOffer(host=host_identity(), md5=String._md5sum, type_name=String._type, qos=SubscribeQoSOptions(),
                     pid=0).to_xmlrpc()
    answer = xmlrpc.client.ServerProxy(uri).requestTopic("/bench_victim", "/bench/victim", [offer])
    time.sleep(3.0)
    after = [e for e in listener.events if e.get("event") == "count"][-1]
    talker.stop()
    listener.stop()
    return {"forged_answer": answer[:2], "received_in_3s_after": after["received"] - before["received"],
            "connections_after": after["connections"], "transports_after": after["transports"]}


def fill(env: Dict[str, str], size_mb: int) -> Dict[str, Any]:
    from micros_rt.transports.shm.host import iceoryx2_root

    root = iceoryx2_root()
    os.makedirs(root, mode=0o700, exist_ok=True)
    holder = subprocess.Popen(["unshare", "-m", "--propagation", "private", "sh", "-c",
                               f"mount -t tmpfs -o size={size_mb}m tmpfs /dev/shm && mount -t tmpfs -o size=16m,"
                               f"mode=0700 tmpfs {root} && echo up && exec sleep 600"],
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "up"
    ns = ["nsenter", "-t", str(holder.pid), "-m", "--"]
    try:
        topic, n = f"/bench/fill_{size_mb}", 100
        listener = Peer([*ns, PY, SEQ, "recv", "--topic", topic, "--count", str(n), "--slow", "0.07", "--idle", "20",
                         "--timeout", "120"], env)
        listener.wait_for(event("ready"))
        talker = Peer([*ns, PY, SEQ, "send", "--topic", topic, "--count", str(n), "--size", str(1 << 20), "--rate",
                       "20", "--progress", "5", "--linger", "2"], env)
        talker.wait_for(lambda e: e.get("event") == "progress" and e["i"] >= 15)
        dd = subprocess.run([*ns, "dd", "if=/dev/zero", "of=/dev/shm/fill", "bs=1M"], capture_output=True, text=True)
        summary = listener.wait_for(event("summary"), 180)
        code = talker.proc.wait(60)
        return {"size_mb": size_mb, "dd": dd.stderr.strip().splitlines()[-1], "talker_exit": code,
                "received": summary["received"], "missing": len(summary["missing"] or []),
                "words": next((line.strip()[:220] for line in talker.stderr if "/dev/shm" in line), "")}
    finally:
        holder.kill()
        holder.wait()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default="sigint,sigint_tcp,sigint_dds,forged,victim,fill")
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--other-runs", type=int, default=10, help="sigint_tcp, sigint_dds: runs each")
    a = ap.parse_args()
    logdir = Path(tempfile.mkdtemp(prefix="micros_rt_shm_faults_"))
    master_proc, master = start_master(logdir)
    env = child_env("micros_rt_shm_local", master, 90 + os.getpid() % 100)
    os.environ.update(ROS_MASTER_URI=master, ROS_IP="127.0.0.1")
    results: Dict[str, Any] = {}
    try:
        parts = a.parts.split(",")
        if "sigint" in parts:
            results["sigint"] = sigint(env, a.runs)
        for hints in ("tcp", "dds"):  # the same stop on the other transports (--parts sigint_tcp,sigint_dds)
            if f"sigint_{hints}" in parts:
                results[f"sigint_{hints}"] = sigint(env, a.other_runs, hints)
        if "forged" in parts:
            results["forged"] = forged(env, master)
        if "victim" in parts:
            results["victim"] = victim(env, master)
        if "fill" in parts:
            results["fill"] = [fill(env, size) for size in (80, 160)]
    finally:
        master_proc.terminate()
        master_proc.wait()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "shm_faults.json").write_text(json.dumps(results, indent=2, default=str))
    lines = ["# Shared memory under faults (benchmarks/shm_faults.py)", ""]
    for name, value in results.items():
        lines.append(f"- **{name}**: `{json.dumps(value, default=str)}`")
    (RESULTS / "shm_faults.md").write_text("\n".join(lines) + "\n")
    print(json.dumps(results, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
