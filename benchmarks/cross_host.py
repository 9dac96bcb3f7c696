#!/usr/bin/env python3
"""Cross-host benchmark: stock rospy TCPROS, micros_rt DDS and micros_rt's TCPROS fallback between hosts in
network namespaces this script makes and removes (issue 20; run as root).

    .venv/bin/python benchmarks/cross_host.py            # MTU 1500 and 9000, every figure, 1 round (~8 min)
    .venv/bin/python benchmarks/cross_host.py --quick    # MTU 1500, the stream and fan-out figures only
    .venv/bin/python benchmarks/cross_host.py --mtus 1500 --figures stream,fanout4 --only mrt_dds,rospy
    .venv/bin/python benchmarks/cross_host.py --rates none,1gbit --figures stream,fanout4   # also a GigE LAN

Hosts: five namespaces joined by veth pairs (every link at the MTU of the run) to a Linux bridge in a
namespace of its own (tests/netns.py), unshaped or (--rates) every host's egress at a line rate (tbf, 20 ms
queue: a wired LAN's NICs, whose wire time an unshaped veth pair does not have); the publisher (or pinger) on
host 0, subscribers on hosts 1..4; a rosmaster on host 0. micros_rt in its default configuration (it follows
ROS_IP: the host's interface), stock rospy with tcp_nodelay. Every endpoint is its own process
(benchmarks/peer.py for round trips and one-way rates, benchmarks/cross_host_peer.py for the paced streams).

Figures (per MTU and stack):
  rtt       round trip host 0 -> host 1 -> host 0: 64 B, 64 KiB, LaserScan, Image 640x480, PointCloud2 1 MiB
            (p50, p99 microseconds; lost = no answer within 2 s)
  thr       one way host 0 -> host 1 as fast as the sender can (lossless publishers): messages/s, lost
  stream    Image 640x480 rgb8 at 30 Hz, queue 2, to host 1: delivered, one-way latency p50/p99
  fanout4   the same stream to hosts 1..4 at once: per host delivered and latency, and the bytes host 0's
            link carried per message, in copies of the message (1.0: multicast; 4.0: one copy per host)

Settings are named by MTU, and by MTU@rate when shaped ("1500", "1500@1gbit").
Results: benchmarks/results/latest.json under "cross_host" (the rest of the file is left as it is),
cross_host.md and cross_host.png. Nothing leaves the namespaces: the script checks eth0's tx_packets.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from netns import Hosts  # noqa: E402

from micros_rt.qos.links import parse_bandwidth  # noqa: E402  (the units of a profile's links, tc's)

PEER = str(ROOT / "benchmarks" / "peer.py")
STREAM_PEER = str(ROOT / "benchmarks" / "cross_host_peer.py")
RESULTS = ROOT / "benchmarks" / "results"
PY = {"mrt_dds": str(ROOT / ".venv" / "bin" / "python"), "mrt_tcpros": str(ROOT / ".venv" / "bin" / "python"),
      "rospy": "/usr/bin/python3"}
LABEL = {"mrt_dds": "micros_rt DDS", "mrt_tcpros": "micros_rt TCPROS fallback", "rospy": "stock rospy TCPROS"}
BASE = "rospy"
#: one colour per stack in the plot, as in run.py's plots (stock rospy red, micros_rt DDS blue, its TCPROS grey)
COLOURS = {"mrt_dds": "#1f77b4", "mrt_tcpros": "#7f7f7f", "rospy": "#d62728"}
IMAGE = 640 * 480 * 3
# (tag, peer.py kind, size): the round-trip and one-way figures; each group is one pair of processes
# (large messages alone, as benchmarks/run.py does, so no type runs on memory another left)
GROUPS = [[("b64", "bytes", 64), ("b64k", "bytes", 65536), ("scan", "scan", 1081 * 8)],
          [("image_vga", "image_vga", IMAGE)], [("cloud", "cloud", 65536 * 16)]]
THR_GROUPS = [[("b64", "bytes", 64), ("b1m", "bytes", 1 << 20), ("scan", "scan", 1081 * 8)],
              [("image_vga", "image_vga", IMAGE)], [("cloud", "cloud", 65536 * 16)]]
SIZES = {tag: size for group in GROUPS + THR_GROUPS for tag, _, size in group}
TITLES = {"b64": "64 B", "b64k": "64 KiB", "b1m": "1 MiB", "scan": "LaserScan 1,081", "image_vga": "Image 640x480",
          "cloud": "PointCloud2 1 MiB"}
FIGURES = ("rtt", "thr", "stream", "fanout4")


class Peer:
    """One endpoint process in a host; its JSON lines are collected by a thread."""

    def __init__(self, hosts: Hosts, host: int, argv: List[str], cyclone_xml: str = "") -> None:
        self.events: "queue.Queue[Dict[str, Any]]" = queue.Queue()
        self.seen: List[Dict[str, Any]] = []
        env = hosts.env(host)
        if cyclone_xml:  # an experiment: a Cyclone configuration instead of micros_rt's network one
            env["CYCLONEDDS_URI"] = cyclone_xml.replace("{ip}", hosts.ip(host))
        self.p = subprocess.Popen(hosts.run(host, argv), env=env, text=True, stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            try:
                self.events.put(json.loads(line))
            except ValueError:
                continue

    def wait(self, ev: str, timeout: float, **match: Any) -> Dict[str, Any]:
        for e in self.seen:
            if e.get("ev") == ev and all(e.get(k) == v for k, v in match.items()):
                self.seen.remove(e)
                return e
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise RuntimeError(f"no {ev} event within {timeout:.0f} s")
            try:
                e = self.events.get(timeout=left)
            except queue.Empty:
                continue
            if e.get("ev") == "error":
                raise RuntimeError(f"peer failed: {e.get('error')}")
            if e.get("ev") == ev and all(e.get(k) == v for k, v in match.items()):
                return e
            self.seen.append(e)

    def send(self, line: str) -> None:
        try:
            assert self.p.stdin is not None
            self.p.stdin.write(line + "\n")
            self.p.stdin.flush()
        except (BrokenPipeError, OSError):
            pass

    def stop(self) -> None:
        try:
            if self.p.stdin is not None:
                self.p.stdin.close()
        except OSError:
            pass
        try:
            self.p.wait(5)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait(5)


def link_tx(hosts: Hosts, i: int) -> Tuple[int, int]:
    """(bytes, packets) host ``i``'s link has sent (a veth counts a TCP segmentation-offload skb as one)."""
    out = subprocess.run(["ip", "-n", hosts.names[i], "-s", "-j", "link", "show", "dev", hosts.link_name(i)],
                         capture_output=True, text=True, check=True, timeout=10).stdout
    tx = json.loads(out)[0]["stats64"]["tx"]
    return int(tx["bytes"]), int(tx["packets"])


def pct(values: List[float], q: float) -> Optional[float]:
    if not values:
        return None
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


class Bench:
    def __init__(self, hosts: Hosts, P: Dict[str, Any]) -> None:
        self.hosts, self.P, self.n = hosts, P, 0

    def topic(self, what: str) -> str:
        self.n += 1
        return f"/xh_{what}_{self.n}"

    def peer(self, impl: str, host: int, role: str, args: List[Any], stream: bool = False) -> Peer:
        script = STREAM_PEER if stream else PEER
        xml = self.P.get("cyclone_xml", "") if impl.startswith("mrt") else ""
        return Peer(self.hosts, host, [PY[impl], script, impl, role, *[str(a) for a in args]], xml)

    def rtt(self, impl: str, group: List[Any]) -> Dict[str, Any]:
        P = self.P
        specs = ",".join(f"{kind}:{size}:{P['rtt_n'] if size < 100000 else P['rtt_big_n']}:"
                         f"{10 if size > 100000 else 50}:{P['rtt_s']}" for _, kind, size in group)
        common = ["--topic", self.topic("rtt"), "--specs", specs, "--timeout", 120]
        echo = self.peer(impl, 1, "echo", common)
        ping = None
        out: Dict[str, Any] = {}
        try:
            echo.wait("ready", 40)
            ping = self.peer(impl, 0, "ping", common)
            for i, (tag, _, _) in enumerate(group):
                r = ping.wait("result", 90, i=i)
                rtts = r["rtts"]
                out[tag] = {"p50_us": pct(rtts, 0.5), "p99_us": pct(rtts, 0.99), "n": len(rtts), "lost": r["lost"]}
        finally:
            for p in (ping, echo):
                if p is not None:
                    p.stop()
        return out

    def thr(self, impl: str, group: List[Any]) -> Dict[str, Any]:
        P = self.P
        specs = ",".join(f"{kind}:{size}:{10 ** 7}:0:{P['thr_s']}" for _, kind, size in group)
        common = ["--topic", self.topic("thr"), "--specs", specs, "--timeout", 120]
        recv = self.peer(impl, 1, "recv", [*common, "--drain", 2.0])
        send = None
        out: Dict[str, Any] = {}
        try:
            recv.wait("ready", 40)
            send = self.peer(impl, 0, "send", [*common, "--seconds", P["thr_s"], "--subs", 1])
            for i, (tag, _, size) in enumerate(group):
                s = send.wait("sent", 60, i=i)
                recv.send(f"SENT {i} {s['sent']}")
                r = recv.wait("result", 40, i=i)
                send.send(f"NEXT {i}")
                got = r["received"]
                rate = (got - 1) / r["span_s"] if r["span_s"] else 0.0
                out[tag] = {"msgs_per_s": rate, "MB_per_s": rate * size / 1e6, "sent": s["sent"],
                            "lost": s["sent"] - got}
        finally:
            for p in (send, recv):
                if p is not None:
                    p.stop()
        return out

    def stream(self, impl: str, subs: int) -> Dict[str, Any]:
        P = self.P
        common = ["--topic", self.topic("stream"), "--kind", "image_vga", "--rate", P["rate"], "--seconds",
                  P["stream_s"], "--queue", 2, "--timeout", 90]
        sinks = [self.peer(impl, 1 + j, "sink", common, stream=True) for j in range(subs)]
        src = None
        try:
            for s in sinks:
                s.wait("ready", 40)
            src = self.peer(impl, 0, "stream", [*common, "--subs", subs], stream=True)
            src.wait("ready", 60)
            tx0 = link_tx(self.hosts, 0)
            sent = src.wait("sent", P["stream_s"] + 30)
            for s in sinks:
                s.send(f"SENT {sent['sent']}")
            res = [s.wait("result", 30) for s in sinks]
            tx1 = link_tx(self.hosts, 0)
        finally:
            for p in (src, *sinks):
                if p is not None:
                    p.send("DONE")
                    p.stop()
        lat = [x for r in res for x in r["lat_ms"]]
        return {"sent": sent["sent"], "delivered": [r["received"] for r in res],
                "p50_ms": [r["p50_ms"] for r in res], "p99_ms": [r["p99_ms"] for r in res],
                "all_p50_ms": pct(lat, 0.5), "all_p99_ms": pct(lat, 0.99),
                "publisher_cpu_ms_per_msg": sent["cpu_s"] * 1e3 / max(1, sent["sent"]),
                "publish_call_p50_ms": sent.get("publish_p50_ms"),
                "publisher_link_copies": (tx1[0] - tx0[0]) / (IMAGE * max(1, sent["sent"])),
                "publisher_link_packets_per_msg": (tx1[1] - tx0[1]) / max(1, sent["sent"]),
                "cdf_ms": [pct(lat, i / 100) for i in range(100)]}


def shape(hosts: Hosts, rate: str) -> None:
    """Every host's egress at ``rate`` (a profile's bandwidth text: 1gbit, 100Mbit): tbf with a 20 ms queue and
    a bucket of 2 ms of the rate (at least 64 KB, so a segmentation-offloaded TCP segment leaves whole), as a
    wired NIC sends at its line rate."""
    bps = parse_bandwidth(rate)
    bucket = max(65536, int(bps / 8 * 0.002))
    for i in range(hosts.n):
        hosts.sh("ip", "netns", "exec", hosts.names[i], "tc", "qdisc", "add", "dev", hosts.link_name(i), "root",
                 "tbf", "rate", f"{int(bps)}bit", "burst", str(bucket), "latency", "20ms")


def run_mtu(mtu: int, rate: str, impls: List[str], figures: List[str], P: Dict[str, Any], rnd: int,
            results: Dict[str, Any], errors: List[str]) -> None:
    setting = str(mtu) if rate == "none" else f"{mtu}@{rate}"
    hosts = Hosts(5 if "fanout4" in figures else 2, mtu=mtu, plain_bridge=P["plain_bridge"]).up()
    try:
        if rate != "none":
            shape(hosts, rate)
        b = Bench(hosts, P)
        order = impls[rnd % len(impls):] + impls[:rnd % len(impls)]
        for impl in order:
            res = results.setdefault(setting, {}).setdefault(impl, {})
            steps: List[Any] = []
            if "rtt" in figures:
                steps += [("rtt", g) for g in GROUPS]
            if "thr" in figures:
                steps += [("thr", g) for g in THR_GROUPS]
            if "stream" in figures:
                steps.append(("stream", 1))
            if "fanout4" in figures:
                steps.append(("fanout4", 4))
            for kind, arg in steps:
                name = kind if kind in ("stream", "fanout4") else f"{kind} {','.join(t for t, _, _ in arg)}"
                print(f"  {setting} {impl}: {name} ...", flush=True)
                try:
                    if kind == "rtt":
                        for tag, v in b.rtt(impl, arg).items():
                            res.setdefault("rtt", {}).setdefault(tag, []).append(v)
                    elif kind == "thr":
                        for tag, v in b.thr(impl, arg).items():
                            res.setdefault("thr", {}).setdefault(tag, []).append(v)
                    else:
                        res.setdefault(kind, []).append(b.stream(impl, arg))
                except Exception as exc:  # a failed phase is reported, the run goes on
                    errors.append(f"{setting} {impl} {name}: {exc}")
                    print(f"    failed: {exc}", flush=True)
    finally:
        hosts.down()


def med(runs: List[Dict[str, Any]], key: str) -> Optional[float]:
    vals = [r[key] for r in runs if r.get(key) is not None]
    return statistics.median(vals) if vals else None


def summarise(results: Dict[str, Any]) -> Dict[str, Any]:
    """Per MTU and stack the medians over rounds (flat keys), and each figure's ratio to stock rospy."""
    summary: Dict[str, Any] = {}
    for mtu, stacks in results.items():
        for impl, res in stacks.items():
            flat: Dict[str, Any] = {}
            for tag, runs in res.get("rtt", {}).items():
                flat[f"rtt_{tag}_p50_us"] = med(runs, "p50_us")
                flat[f"rtt_{tag}_p99_us"] = med(runs, "p99_us")
                flat[f"rtt_{tag}_lost"] = sum(r["lost"] for r in runs)
            for tag, runs in res.get("thr", {}).items():
                flat[f"thr_{tag}_msgs_per_s"] = med(runs, "msgs_per_s")
                flat[f"thr_{tag}_lost"] = sum(r["lost"] for r in runs)
            for kind in ("stream", "fanout4"):
                runs = res.get(kind, [])
                if not runs:
                    continue
                flat[f"{kind}_p50_ms"] = statistics.median(max(r["p50_ms"]) for r in runs)
                flat[f"{kind}_p99_ms"] = statistics.median(max(r["p99_ms"]) for r in runs)
                flat[f"{kind}_lost"] = sum(r["sent"] * len(r["delivered"]) - sum(r["delivered"]) for r in runs)
                flat[f"{kind}_copies"] = statistics.median(r["publisher_link_copies"] for r in runs)
                flat[f"{kind}_link_packets_per_msg"] = statistics.median(
                    r.get("publisher_link_packets_per_msg", 0.0) for r in runs)
                flat[f"{kind}_pub_cpu_ms_per_msg"] = statistics.median(r["publisher_cpu_ms_per_msg"] for r in runs)
                flat[f"{kind}_publish_call_ms"] = statistics.median(r["publish_call_p50_ms"] or 0.0 for r in runs)
            summary.setdefault(mtu, {})[impl] = flat
    for mtu, stacks in summary.items():
        base = stacks.get(BASE, {})
        for impl, flat in stacks.items():
            if impl == BASE:
                continue
            ratios = {}
            for k, v in flat.items():
                b = base.get(k)
                if v is not None and b and not k.endswith(("_lost", "_copies", "_cpu_ms_per_msg", "_call_ms", "_packets_per_msg")):
                    ratios[k] = v / b
            flat["vs_rospy"] = ratios
    return summary


def eth0_tx() -> Optional[int]:
    try:
        return int(Path("/sys/class/net/eth0/statistics/tx_packets").read_text())
    except OSError:
        return None


def fmt(v: Optional[float], nd: int = 0) -> str:
    return "-" if v is None else f"{v:,.{nd}f}"


def table(summary: Dict[str, Any]) -> List[str]:
    lines = []
    for mtu, stacks in summary.items():
        title = f"MTU {mtu}".replace("@", ", every link at ")
        lines += [title, "", "| figure | " + " | ".join(LABEL[i] for i in stacks) + " |",
                  "|---|" + "---|" * len(stacks)]
        keys: List[str] = []
        for flat in stacks.values():
            keys += [k for k in flat if k not in keys and k != "vs_rospy" and not k.endswith("_lost")]
        for k in keys:
            cells = []
            for impl, flat in stacks.items():
                v = flat.get(k)
                nd = 2 if k.endswith(("_copies", "_ms", "_ms_per_msg", "_call_ms")) else 0
                cell = fmt(v, nd)
                lost_key = k.rsplit("_", 2)[0] + "_lost" if k.endswith(("_p50_us", "_p99_us", "_p50_ms", "_p99_ms"))\
                    else k.rsplit("_", 3)[0] + "_lost"
                if k.endswith(("_msgs_per_s", "_p50_ms")) and flat.get(lost_key):
                    cell += f" ({flat[lost_key]:,} lost)"
                r = flat.get("vs_rospy", {}).get(k)
                if r is not None:
                    cell += f" ({r:.2f}x)"
                cells.append(cell)
            lines.append(f"| {k} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def plot(results: Dict[str, Any], out: Path) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot")
        return
    mtus = list(results)
    fig, axes = plt.subplots(2, len(mtus), figsize=(6 * len(mtus), 8), squeeze=False)
    for col, mtu in enumerate(mtus):
        for row, kind in enumerate(("stream", "fanout4")):
            ax = axes[row][col]
            for impl, res in results[mtu].items():
                for n, run in enumerate(res.get(kind, [])):
                    cdf = [x for x in run.get("cdf_ms", []) if x is not None]
                    if cdf:
                        rounds = len(res.get(kind, []))
                        label = (LABEL[impl] + (f" ({rounds} rounds)" if rounds > 1 else "")) if n == 0 else None
                        ax.plot(cdf, [i / len(cdf) for i in range(len(cdf))], label=label, color=COLOURS[impl])
            hosts = "1 subscriber host" if kind == "stream" else "4 subscriber hosts"
            ax.set_title(f"Image 640x480 30 Hz, {hosts}, MTU {mtu}".replace("@", " at ") + "\n(lower is better)",
                         fontsize=10)
            ax.set_xlabel("one-way latency, ms")
            ax.set_ylabel("fraction of messages")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="lower right")
    fig.suptitle("Between hosts: one-way latency of a 30 Hz camera stream (no target set; lines further left are "
                 "better)")
    fig.tight_layout()
    fig.savefig(out / "cross_host.png", dpi=90)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="MTU 1500, stream and fan-out only, 3 s streams")
    ap.add_argument("--mtus", default=None, help="comma-separated (default 1500,9000)")
    ap.add_argument("--rates", default="none", help="comma-separated line rates of every host's link: none "
                    "(unshaped veth, the default) or a tc rate such as 1gbit")
    ap.add_argument("--figures", default=None, help=f"comma-separated of {','.join(FIGURES)} (default all)")
    ap.add_argument("--only", default="rospy,mrt_dds,mrt_tcpros", help="stacks (rospy, mrt_dds, mrt_tcpros)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=None, help="seconds per stream (default 5; quick 3)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--plain-bridge", action="store_true", help="the bridge as a switch: bridged frames skip the "
                    "firewall (net.bridge.bridge-nf-call-iptables=0 in the bridge's namespace)")
    ap.add_argument("--no-save", action="store_true", help="print only (steering runs)")
    ap.add_argument("--cyclone-xml", default="", help="experiments: CYCLONEDDS_URI for micros_rt's processes "
                    "({ip} stands for the host's address; it replaces micros_rt's network configuration)")
    args = ap.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("cross_host.py makes network namespaces: run it as root")
    mtus = [int(m) for m in (args.mtus or ("1500" if args.quick else "1500,9000")).split(",")]
    rates = args.rates.split(",")
    for rate in rates:
        if rate != "none":
            try:
                parse_bandwidth(rate)
            except ValueError as exc:
                raise SystemExit(f"--rates: {exc}") from None
    figures = (args.figures or ("stream,fanout4" if args.quick else ",".join(FIGURES))).split(",")
    impls = args.only.split(",")
    P = {"rtt_n": 300, "rtt_big_n": 60, "rtt_s": 4.0, "thr_s": 2.0, "rate": 30.0,
         "stream_s": args.seconds or (3.0 if args.quick else 5.0), "cyclone_xml": args.cyclone_xml,
         "plain_bridge": args.plain_bridge}
    os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 200 + 20))
    tx_before = eth0_tx()
    t0 = time.monotonic()
    results: Dict[str, Any] = {}
    errors: List[str] = []
    for rnd in range(args.rounds):
        for rate in rates:
            for mtu in mtus:
                print(f"round {rnd + 1}/{args.rounds}: MTU {mtu}, links {rate}", flush=True)
                run_mtu(mtu, rate, impls, figures, P, rnd, results, errors)
    tx_after = eth0_tx()
    summary = summarise(results)
    lines = table(summary)
    print("\n".join(lines))
    if errors:
        print("errors:\n  " + "\n  ".join(errors))
    eth0 = None if tx_before is None or tx_after is None else tx_after - tx_before
    print(f"eth0 tx packets during the run: {eth0}; {time.monotonic() - t0:.0f} s")
    if args.no_save:
        print(json.dumps(summary, indent=1))
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for stacks in results.values():  # the per-message latencies stay out of latest.json (the CDF stays)
        for res in stacks.values():
            for kind in ("stream", "fanout4"):
                for run in res.get(kind, []):
                    run.pop("lat_ms", None)
    command = " ".join([".venv/bin/python", "benchmarks/cross_host.py", *sys.argv[1:]])
    run = {"command": command, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "rounds": args.rounds,
           "figures": figures, "params": P, "wall_s": round(time.monotonic() - t0, 1),
           "eth0_tx_packets_during_run": eth0, "errors": errors, "stacks": {i: LABEL[i] for i in impls}}
    latest = out / "latest.json"
    data = json.loads(latest.read_text()) if latest.exists() else {}
    # settings (MTU, rate) this run did not measure stay as an earlier run left them; each names its run
    # (ratios are only ever taken within one setting, whose stacks ran in the same run)
    prev = data.get("cross_host", {})
    prev_run = prev.get("by_setting") or {k: {key: prev.get(key) for key in ("command", "wall_s", "rounds")}
                                          for k in prev.get("summary", {})}
    keep = [k for k in prev.get("summary", {}) if k not in summary]
    data["cross_host"] = {
        **run, "by_setting": {**{k: prev_run.get(k) for k in keep}, **{k: run for k in summary}},
        "summary": {**{k: prev["summary"][k] for k in keep}, **summary},
        "runs": {**{k: prev.get("runs", {}).get(k, {}) for k in keep}, **results}}
    latest.write_text(json.dumps(data, indent=1))
    merged = data["cross_host"]
    (out / "cross_host.md").write_text("\n".join(table(merged["summary"])) + "\n")
    plot(merged["runs"], out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
