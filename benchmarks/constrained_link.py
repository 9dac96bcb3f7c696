"""Constrained-link benchmark: a 1 kHz control topic and a 30 Hz 640x480 camera from one process, across a
shaped link between two hosts (network namespaces this script makes and removes), stock rospy TCPROS and
micros_rt in the same run (issue 19's scenarios; run as root).

    .venv/bin/python benchmarks/constrained_link.py                  # both links, 10 s per run, 1 round
    .venv/bin/python benchmarks/constrained_link.py --seconds 6 --links tbf

Links (the publisher host's egress; the subscriber host's is unshaped):
  tbf   40 Mbit/s, a 50 ms FIFO queue (tbf): a radio link's bottleneck
  htb   40 Mbit/s, DSCP honoured: htb with two classes, AF4x/EF/CS5-7 first (as Wi-Fi WMM or a DiffServ
        router), each class with a 50 ms pfifo

micros_rt: /control at TransportPriority.HIGH (DSCP AF41), /image at LOW (CS1: its writer is on a participant of
its own, with its own sockets); rospy: tcp_nodelay subscribers.
Both in their default configuration otherwise. relay (with --stacks rospy,micros_rt,relay): two robots, each its
own rosmaster; the stock rospy publisher and subscriber of the rospy stack, with ``micros-rt relay`` on each
host carrying /control (HIGH, history 100) and /image (LOW, history 2) between the graphs over DDS;
relay_capped: the same with the camera exported at ``max_rate: 2`` (15 Mbit/s of the 40; 5 Hz would be 37);
micros_rt_tcp: micros_rt with the camera over TCPROS (the subscriber's profile: ``/image: {transport_hints:
[TCPROS]}``); micros_rt_paced: the sending robot's profile alone, serving the camera over TCPROS only
(``publishers: {/image: {transport_hints: [TCPROS]}}``) and naming the link (``links: {radio: {peers:
[<far host>], bandwidth: 40Mbit}}``), so the camera's TCP connection is paced at 36 Mbit/s; the subscriber has
no profile. micros_rt_link: both topics on DDS, the publisher's profile naming the link alone (``links:``): the
camera's writer, below HIGH, is on a participant of its own whose UDP send buffer is 16.5 kB.
relay_link: robot A's relay told the link's rate (``link_bandwidth: 40Mbit``: its LOW process asks for a
16.5 kB UDP send buffer, so it never queues more than ~33 kB in the link);
relay_one_process: robot A's relay with ``--one-process`` (both exports in one process, so both carry the DSCP of
HIGH; by default the relay runs a process per priority). Each endpoint is its own process
(tests/peers/mrt_link.py). Results: benchmarks/results/latest.json under "constrained_link" (the rest of
the file is left as it is), constrained_link.md and constrained_link.png (control latency distribution
per link and stack). Nothing leaves the namespaces: the script checks eth0's tx_packets.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

ROOT = Path(__file__).resolve().parents[1]
PEER = ROOT / "tests" / "peers" / "mrt_link.py"
MRT_PYTHON = str(ROOT / ".venv" / "bin" / "python")
STOCK_PYTHON = "/usr/bin/python3"
RESULTS = ROOT / "benchmarks" / "results"
# the classes the htb link serves first: DSCP AF41-43, CS5, EF, CS6, CS7 (TOS byte, mask 0xfc)
PRIORITY_TOS = ("0x88", "0x90", "0x98", "0xa0", "0xb8", "0xc0", "0xe0")


def sh(*argv: str) -> None:
    subprocess.run(list(argv), check=True, capture_output=True, timeout=20)


class Link:
    """Two hosts joined by a veth pair; the publisher host's egress shaped as ``kind`` says; ``loopback``:
    one namespace, both ends on its 127.0.0.1 (a host's CPU as the bottleneck, no link).

    Also examples/relay_demo.py's two robots (``names``: its namespaces' names).
    """

    def __init__(self, kind: str, masters: int = 1, mtu: int = 1500, names: Optional[List[str]] = None) -> None:
        pid = os.getpid()
        self.mtu = mtu
        self.masters = masters
        self.robot_masters: List["subprocess.Popen[bytes]"] = []
        self.kind = kind
        self.ns = names or [f"mrtCL{i}_{pid}" for i in range(2)]
        self.dev = [f"cl{i}_{pid}"[:15] for i in range(2)]
        self.ip = [f"10.79.{pid % 200 + 20}.{i + 1}" for i in range(2)]
        if kind == "loopback":
            self.ns, self.ip = [self.ns[0]] * 2, ["127.0.0.1"] * 2
        self.master: Optional["subprocess.Popen[bytes]"] = None

    def up(self) -> "Link":
        if self.kind == "loopback":
            sh("ip", "netns", "add", self.ns[0])
            sh("ip", "-n", self.ns[0], "link", "set", "lo", "up")
            return self._masters_up()
        for ns in self.ns:
            sh("ip", "netns", "add", ns)
        sh("ip", "link", "add", self.dev[0], "mtu", str(self.mtu), "type", "veth", "peer", "name", self.dev[1], "mtu",
           str(self.mtu))
        for i in range(2):
            sh("ip", "link", "set", self.dev[i], "netns", self.ns[i])
            sh("ip", "-n", self.ns[i], "addr", "add", f"{self.ip[i]}/24", "dev", self.dev[i])
            sh("ip", "-n", self.ns[i], "link", "set", self.dev[i], "up")
            sh("ip", "-n", self.ns[i], "link", "set", "lo", "up")
        tc = ["ip", "netns", "exec", self.ns[0], "tc"]
        dev = self.dev[0]
        if self.kind == "none":
            pass  # an unshaped veth pair: what a relay costs by itself
        elif self.kind == "tbf":
            sh(*tc, "qdisc", "add", "dev", dev, "root", "tbf", "rate", "40mbit", "burst", "32kbit", "latency", "50ms")
        else:
            sh(*tc, "qdisc", "add", "dev", dev, "root", "handle", "1:", "htb", "default", "20")
            sh(*tc, "class", "add", "dev", dev, "parent", "1:", "classid", "1:1", "htb", "rate", "40mbit")
            for cls, prio in (("1:10", "0"), ("1:20", "1")):
                sh(*tc, "class", "add", "dev", dev, "parent", "1:1", "classid", cls, "htb", "rate", "20mbit",
                   "ceil", "40mbit", "prio", prio)
                # 50 ms at 40 Mbit/s of 1,500 B packets
                sh(*tc, "qdisc", "add", "dev", dev, "parent", cls, "pfifo", "limit", "166")
            for tos in PRIORITY_TOS:
                sh(*tc, "filter", "add", "dev", dev, "parent", "1:", "protocol", "ip", "prio", "1", "u32", "match",
                   "ip", "tos", tos, "0xfc", "flowid", "1:10")
        return self._masters_up()

    def _masters_up(self) -> "Link":
        for i in range(self.masters):
            self.robot_masters.append(subprocess.Popen(
                ["ip", "netns", "exec", self.ns[i], "/usr/bin/rosmaster", "--core", "-p", "11311"],
                env=self.env(i), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            deadline = time.monotonic() + 20
            while True:
                probe = subprocess.run(["ip", "netns", "exec", self.ns[i], STOCK_PYTHON, "-c",
                                        f"import xmlrpc.client as x; x.ServerProxy('http://{self.ip[i]}:11311')"
                                        f".getPid('/t')"], capture_output=True, timeout=10)
                if probe.returncode == 0:
                    break
                if time.monotonic() > deadline:
                    raise SystemExit(f"rosmaster did not come up in namespace {self.ns[i]}")
                time.sleep(0.2)
        self.master = self.robot_masters[0]
        return self

    def env(self, i: int) -> Dict[str, str]:
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("ROS_", "CYCLONEDDS", "PYTHONPATH", "MICROS_RT"))}
        master = self.ip[i] if self.masters > 1 else self.ip[0]  # each robot its own master, or one for both
        env.update(ROS_MASTER_URI=f"http://{master}:11311", ROS_IP=self.ip[i],
                   ROS_DOMAIN_ID=str(os.getpid() % 200 + 20), PYTHONUNBUFFERED="1",
                   ROS_HOME=f"/tmp/{self.ns[0]}", ROS_LOG_DIR=f"/tmp/{self.ns[0]}")
        return env

    def run(self, i: int, argv: List[str], stderr: Any = subprocess.DEVNULL,
            env: Optional[Dict[str, str]] = None) -> "subprocess.Popen[str]":
        return subprocess.Popen(["ip", "netns", "exec", self.ns[i], *argv], env={**self.env(i), **(env or {})},
                                text=True, stdout=subprocess.PIPE, stderr=stderr)

    def down(self) -> None:
        for master in self.robot_masters:
            master.terminate()
            try:
                master.wait(5)
            except subprocess.TimeoutExpired:
                master.kill()
        for ns in dict.fromkeys(self.ns):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=20)


def events(proc: "subprocess.Popen[str]", timeout: float) -> List[Dict[str, Any]]:
    """Every JSON line ``proc`` prints until it exits (killed after ``timeout`` s)."""
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    found = []
    for line in out.splitlines():
        try:
            found.append(json.loads(line))
        except ValueError:
            continue
    return found


RELAY_EXPORT = ("graph: robot_a\nexport:\n  /control: {transport_priority: HIGH, queue_size: 100}\n"
                "  /image: {transport_priority: LOW, queue_size: 2%s}\n")
RELAY_IMPORT = ("graph: robot_b\nimport:\n  /robot_a/control: {as: /control, queue_size: 100}\n"
                "  /robot_a/image: {as: /image, queue_size: 2}\n")


def profiles(stack: str, directory: Path, far_host: str) -> Tuple[Dict[str, str], Dict[str, str]]:
    """The publisher's and the subscriber's environment for a micros_rt stack: micros_rt_tcp, the camera over
    TCPROS (the subscriber's profile); micros_rt_paced, the camera over TCPROS and the link, both in the
    publisher's profile."""
    pub: Dict[str, str] = {}
    sub: Dict[str, str] = {}
    if stack == "micros_rt_tcp":
        (directory / "sub.yaml").write_text("subscribers:\n  /image: {transport_hints: [TCPROS]}\n")
        sub["MICROS_RT_QOS_PROFILE"] = str(directory / "sub.yaml")
    if stack == "micros_rt_paced":
        (directory / "pub.yaml").write_text("publishers:\n  /image: {transport_hints: [TCPROS]}\n"
                                            f"links:\n  radio: {{peers: [{far_host}], bandwidth: 40Mbit}}\n")
        pub["MICROS_RT_QOS_PROFILE"] = str(directory / "pub.yaml")
    if stack == "micros_rt_link":
        (directory / "pub.yaml").write_text(f"links:\n  radio: {{peers: [{far_host}], bandwidth: 40Mbit}}\n")
        pub["MICROS_RT_QOS_PROFILE"] = str(directory / "pub.yaml")
    return pub, sub


def one_run(kind: str, stack: str, seconds: float, image: List[str], mtu: int = 1500) -> Dict[str, Any]:
    relayed = stack.startswith("relay")
    link = Link(kind, masters=2 if relayed else 1, mtu=mtu)
    relays: List["subprocess.Popen[str]"] = []
    try:
        link.up()
        mrt = stack.startswith("micros_rt")
        python = MRT_PYTHON if mrt else STOCK_PYTHON
        extra = [] if mrt else ["--stock"]
        config = Path(f"/tmp/{link.ns[0]}")
        config.mkdir(parents=True, exist_ok=True)
        pub_env, sub_env = profiles(stack, config, link.ip[1])
        if relayed:  # the relays start first; the far side's subscriber connects seconds after the near one
            cap = ", max_rate: 2" if stack == "relay_capped" else ""
            link_line = "link_bandwidth: 40Mbit\n" if stack == "relay_link" else ""
            for i, text in enumerate((RELAY_EXPORT % cap + link_line, RELAY_IMPORT)):
                (config / f"relay{i}.yaml").write_text(text)
                one = ["--one-process"] if stack == "relay_one_process" and i == 0 else []
                relays.append(link.run(i, [str(ROOT / ".venv" / "bin" / "micros-rt"), "relay", "--config",
                                           str(config / f"relay{i}.yaml"), "--poll-period", "0.3", "--json",
                                           "--stats-period", "2", *one]))
        sub = link.run(1, [python, str(PEER), "sub", "--seconds", str(seconds + 60), *extra, *image], env=sub_env)
        pub_extra = ["--start-delay", "8"] if relayed else []
        pub = link.run(0, [python, str(PEER), "pub", "--seconds", str(seconds), *extra, *pub_extra, *image],
                       env=pub_env)
        published, summary = outcome(pub, sub, seconds)
    finally:
        relay_stats = stop_relays(relays)
        link.down()
        shutil.rmtree(f"/tmp/{link.ns[0]}", ignore_errors=True)  # the relays' configs, ROS_HOME and logs
    if published is None or summary is None:
        return {"error": f"no {'published' if published is None else 'summary'} event"}
    intended = published["intended_control"]
    return {"control_published": published["control"], "control_intended": intended,
            "control_published_share": published["control"] / intended,
            "control_delivered": summary["control"], "control_p50_ms": summary["p50_ms"],
            "control_p99_ms": summary["p99_ms"], "control_max_ms": summary["max_ms"],
            "images_published": published["image"], "images_delivered": summary["image"],
            "image_p50_ms": summary["image_p50_ms"], "transports": summary["transports"],
            "image_transports": summary.get("image_transports", []),
            "publisher_statistics": published.get("statistics") or {}, "control_cdf_ms": summary["control_cdf_ms"],
            **({"relay_statistics": relay_stats} if relays else {})}


def outcome(pub: "subprocess.Popen[str]", sub: "subprocess.Popen[str]",
            seconds: float) -> Tuple[Optional[Dict[str, Any]], Optional[Dict[str, Any]]]:
    """The publisher's ``published`` and the subscriber's ``summary`` events (tests/peers/mrt_link.py)."""
    published = next((e for e in events(pub, seconds + 120) if e.get("event") == "published"), None)
    summary = next((e for e in events(sub, 90) if e.get("event") == "summary"), None)
    return published, summary


def stop_relays(relays: List["subprocess.Popen[str]"]) -> List[Optional[Dict[str, Any]]]:
    """Stop ``micros-rt relay --json`` processes; each one's last ``stats`` event."""
    found = []
    for relay in relays:
        relay.terminate()
        found.append(next((e for e in reversed(events(relay, 10)) if e.get("event") == "stats"), None))
    return found


def markdown_table(columns: List[str], results: Dict[str, Dict[str, List[Dict[str, Any]]]],
                   cells: Callable[[Dict[str, Any]], List[str]]) -> List[str]:
    """A markdown table of ``results[group][stack]`` runs: the group, the stack, then ``cells(run)`` (a run with
    an ``error`` shows it instead)."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for group, stacks in results.items():
        for stack, runs in stacks.items():
            for run in runs:
                row = [run["error"]] + [""] * (len(columns) - 3) if "error" in run else cells(run)
                lines.append("| " + " | ".join([group, stack, *row]) + " |")
    return lines


def eth0_tx() -> Optional[int]:
    try:
        return int(Path("/sys/class/net/eth0/statistics/tx_packets").read_text())
    except OSError:
        return None


#: one colour per stack, the same in every round (stock rospy red and micros_rt's DDS blue, as in run.py's plots)
STACK_COLOURS = {"rospy": "#d62728", "micros_rt": "#1f77b4", "micros_rt_link": "#17becf", "micros_rt_tcp": "#7f7f7f",
                 "micros_rt_paced": "#2ca02c", "relay": "#9467bd", "relay_link": "#e377c2", "relay_capped": "#bcbd22",
                 "relay_one_process": "#8c564b"}
#: issue 19's targets for the control topic's p99 (ms; also at most 0.5x rospy's in the same run)
TARGET_P99_MS = {"tbf": 10.0, "htb": 5.0, "loopback": 2.0}


def plot(results: Dict[str, Dict[str, List[Dict[str, Any]]]], path: Path) -> None:
    """The control topic's latency distribution per link: one colour and one legend entry per stack (a line per
    round), issue 19's p99 target as a dashed line. ``results`` is ``latest.json["constrained_link"]["links"]``
    (or relay_link.json's ``links``), so a plot is redrawn from committed results without re-running."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot")
        return
    fig, axes = plt.subplots(1, len(results), figsize=(6.5 * len(results), 4.4), squeeze=False)
    for ax, (kind, stacks) in zip(axes[0], results.items()):
        for i, (stack, runs) in enumerate(stacks.items()):
            colour = STACK_COLOURS.get(stack, f"C{i % 10}")
            labelled = False
            for run in runs:
                cdf = run.get("control_cdf_ms") or []
                if cdf:
                    label = None if labelled else f"{stack} ({len(runs)} rounds)" if len(runs) > 1 else stack
                    ax.plot(cdf, [j / len(cdf) for j in range(len(cdf))], color=colour, label=label, alpha=0.85)
                    labelled = True
        target = TARGET_P99_MS.get(kind)
        if target is not None:
            ax.axvline(target, color="black", linestyle="--", linewidth=1,
                       label=f"target: p99 <= {target:g} ms (issue 19)")
            ax.axhline(0.99, color="grey", linestyle=":", linewidth=0.8, label="p99")
        link = {"tbf": "40 Mbit/s FIFO (tbf)", "htb": "40 Mbit/s, DSCP honoured (htb)"}.get(kind, kind)
        ax.set_title(f"{link}: 1 kHz control latency beside a camera\n(lower is better: lines further left)", fontsize=10)
        ax.set_xlabel("control message latency, ms (log scale)")
        ax.set_ylabel("fraction of control messages")
        ax.set_xscale("log")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--links", default="tbf,htb",
                    help="tbf, htb, none (unshaped), loopback (one host: both ends on 127.0.0.1); comma-separated")
    ap.add_argument("--image-size", default="640x480", help="the camera's WIDTHxHEIGHT")
    ap.add_argument("--mtu", type=int, default=1500, help="the link's MTU (9000: jumbo frames)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--stacks", default="rospy,micros_rt,micros_rt_link,micros_rt_tcp,micros_rt_paced",
                    help="rospy, micros_rt, micros_rt_link (both topics on DDS, the link in the publisher's "
                         "profile), micros_rt_tcp (camera over TCPROS), micros_rt_paced (the camera on "
                         "TCPROS and the link, both in the publisher's profile), relay, relay_link (relay A told "
                         "the link's rate), relay_capped (the camera exported at 2 Hz), "
                         "relay_one_process; comma-separated")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("constrained_link.py makes network namespaces and qdiscs: run it as root")
    if "loopback" in args.links.split(",") and any(stack.startswith("relay") for stack in args.stacks.split(",")):
        raise SystemExit("--links loopback is one host with one master; the relay stacks need two robots (tbf, htb, none)")
    tx_before = eth0_tx()
    t0 = time.monotonic()
    results: Dict[str, Dict[str, List[Dict[str, Any]]]] = {}
    for r in range(args.rounds):
        for kind in args.links.split(","):
            stacks = args.stacks.split(",")
            for stack in (stacks if r % 2 == 0 else stacks[::-1]):
                print(f"round {r + 1}/{args.rounds}: {kind} link, {stack} ...", flush=True)
                width, height = args.image_size.split("x")
                results.setdefault(kind, {}).setdefault(stack, []).append(
                    one_run(kind, stack, args.seconds, ["--width", width, "--height", height], args.mtu))
    tx_after = eth0_tx()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = {"seconds": args.seconds, "rounds": args.rounds, "wall_s": round(time.monotonic() - t0, 1),
              "command": " ".join([".venv/bin/python", "benchmarks/constrained_link.py", *sys.argv[1:]]),
              "eth0_tx_packets_during_run": None if tx_before is None or tx_after is None else tx_after - tx_before,
              "links": results}
    latest = out / "latest.json"
    data = json.loads(latest.read_text()) if latest.exists() else {}
    data["constrained_link"] = report
    latest.write_text(json.dumps(data, indent=1))
    lines = markdown_table(
        ["link", "stack", "control published", "delivered", "p50 ms", "p99 ms", "images published / delivered",
         "image p50 ms"], results,
        lambda run: [f"{run['control_published']:,} of {run['control_intended']:,} "
                     f"({run['control_published_share']:.1%})", f"{run['control_delivered']:,}",
                     f"{run['control_p50_ms']:.1f}", f"{run['control_p99_ms']:.1f}",
                     f"{run['images_published']} / {run['images_delivered']}", f"{run['image_p50_ms']:.0f}"])
    (out / "constrained_link.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"eth0 tx packets during the run: {report['eth0_tx_packets_during_run']}")
    plot(results, out / "constrained_link.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
