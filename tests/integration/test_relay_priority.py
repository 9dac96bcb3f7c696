"""Relayed topics on a radio link that honours DSCP (issues 19 and 21): two robots in network namespaces, each
its own rosmaster, robot A's egress at 40 Mbit/s with an htb that serves DSCP AF4x/EF/CS5-7 first (as Wi-Fi WMM
or a DiffServ router does). Stock rospy nodes on both sides: robot A publishes a 1 kHz control topic and a 30 Hz
640x480 camera (about 221 Mbit/s of demand) from one process, robot B subscribes.

Robot A's relay exports /control at HIGH and /image at LOW, so it runs a process per priority (Cyclone marks a
process's DDS packets with one DSCP): the control topic's packets go in the link's priority class and do not
queue behind the camera's. In one process (``--one-process``) every packet carries AF41 and the control topic
waits behind the camera in the link's queue (measured: p50 40 ms, p99 126 ms; with a process per priority 0.6 /
6.0 ms; stock rospy's TCPROS 11.1 / 63.7 ms).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from pathlib import Path
from typing import Any, Dict, Iterator, List, Tuple

import pytest

import harness
from helpers import stock_listener, stock_talker
from test_relay import CLI, Robots, relay, robots  # noqa: F401  (robots: the two-master fixture)

LINK = str(harness.PEERS_DIR / "mrt_link.py")
SECONDS = 6.0


@pytest.fixture
def robots_on_radio(dds_domain: int) -> Iterator[Robots]:
    robots = Robots(2)
    try:
        robots.up()
        robots.hosts.shape_htb_dscp(0)
        yield robots
    finally:
        robots.down()


@pytest.fixture
def robots_on_fifo_radio(dds_domain: int) -> Iterator[Robots]:
    robots = Robots(2)
    try:
        robots.up()
        hosts = robots.hosts   # robot A's egress: 40 Mbit/s, one 50 ms FIFO queue (nothing honours DSCP)
        hosts.sh("ip", "netns", "exec", hosts.names[0], "tc", "qdisc", "add", "dev", hosts.link_name(0), "root",
                 "tbf", "rate", "40mbit", "burst", "32kbit", "latency", "50ms")
        yield robots
    finally:
        robots.down()


def _camera_and_control(robots: Robots, spawn: harness.Spawner, tmp_path: Path, a_extra: str = "") -> Dict[str, Any]:
    """A stock publisher of /control (1 kHz) and /image (640x480, 30 Hz) in robot A, relayed (HIGH, LOW) to a
    stock subscriber in robot B for SECONDS: the publisher's and subscriber's events, link bytes per htb class,
    relay A's stats and process."""
    hosts, (env_a, env_b) = robots.hosts, robots.env
    (tmp_path / "a.yaml").write_text("graph: robot_a\nexport:\n"
                                     "  /control: {transport_priority: HIGH, queue_size: 100}\n"
                                     "  /image: {transport_priority: LOW, queue_size: 2}\n" + a_extra)
    (tmp_path / "b.yaml").write_text("graph: robot_b\nimport:\n  /robot_a/control: {as: /control, queue_size: 100}\n"
                                     "  /robot_a/image: {as: /image, queue_size: 2}\n")
    relay = [CLI, "relay", "--json", "--stats-period", "1", "--poll-period", "0.3", "--config"]
    relay_a = spawn(hosts.run(0, [*relay, str(tmp_path / "a.yaml")]), env=env_a, name="relay_a")
    spawn(hosts.run(1, [*relay, str(tmp_path / "b.yaml")]), env=env_b, name="relay_b")
    sub = spawn(hosts.run(1, [harness.STOCK_PYTHON, LINK, "sub", "--stock", "--seconds", "120"]), env=env_b,
                name="sub")
    start = tmp_path / "start"
    pub = spawn(hosts.run(0, [harness.STOCK_PYTHON, LINK, "pub", "--stock", "--seconds", str(SECONDS),
                              "--start-file", str(start), "--wait-subscribers", "90"]), env=env_a, name="pub")
    assert pub.wait_for("ready", 90)["control"] >= 1
    sub.wait_for("connected", 90)   # A's stock publisher -> relays -> B's stock subscriber, both topics
    before = hosts.class_bytes(0)
    start.touch()
    published = pub.wait_for("published", SECONDS + 90)
    summary = sub.wait_for("summary", 120)
    sent = {cls: n - before.get(cls, 0) for cls, n in hosts.class_bytes(0).items()}
    stats = relay_a.wait_for(lambda e: e.get("event") == "stats" and len(e["exports"]) == 2, 30)
    return {"published": published, "summary": summary, "sent": sent, "stats": stats, "relay_a": relay_a,
            "send_buffers": _send_buffers(hosts, relay_a.proc.pid)}


def test_a_process_per_priority_puts_relayed_control_first_on_a_link_that_honours_dscp(
        robots_on_radio: Robots, spawn: harness.Spawner, tmp_path: Path) -> None:
    run = _camera_and_control(robots_on_radio, spawn, tmp_path)
    published, summary, sent, stats = run["published"], run["summary"], run["sent"], run["stats"]
    print(f"\nrelayed over 40 Mbit/s htb (DSCP honoured), a process per priority: control delivered "
          f"{summary['control']} of {published['control']}, p50 {summary['p50_ms']:.1f} ms, p99 "
          f"{summary['p99_ms']:.1f} ms; images {summary['image']}; link bytes by class {sent}")
    # one relay process per priority, each a node of robot A's graph
    assert sorted(e["process"] for e in stats["exports"]) == ["/relay_robot_a_high", "/relay_robot_a_low"], stats
    # the camera's packets went in the default class, the control topic's in the priority class (one process
    # would have marked all of them AF41: everything in 1:10)
    assert sent["1:20"] > 10_000_000 and sent["1:10"] < sent["1:20"] / 4, sent
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    # in one process: p50 40 ms (the link's queue); a process per priority 0.6 ms
    assert summary["p50_ms"] < 10.0, summary
    assert summary["image"] >= 10, summary


def test_link_bandwidth_keeps_the_low_process_short_in_a_fifo_link(
        robots_on_fifo_radio: Robots, spawn: harness.Spawner, tmp_path: Path) -> None:
    # On a FIFO link nothing tells the processes' packets apart: the LOW process's camera datagrams fill the
    # 50 ms queue (control p50/p99 23-25/31-32 ms through relays, benchmarks/results/relay_link.md). Told the
    # link's rate, the LOW process asks for a 16.5 kB send buffer, and never has more than ~33 kB queued.
    run = _camera_and_control(robots_on_fifo_radio, spawn, tmp_path, "link_bandwidth: 40Mbit\n")
    published, summary, relay_a = run["published"], run["summary"], run["relay_a"]
    print(f"\nrelayed over 40 Mbit/s tbf (FIFO), link_bandwidth 40Mbit: control delivered {summary['control']} of "
          f"{published['control']}, p50 {summary['p50_ms']:.1f} ms, p99 {summary['p99_ms']:.1f} ms; images "
          f"{summary['image']}")
    buffers = run["send_buffers"]
    print(f"UDP send buffers (SO_SNDBUF as the kernel holds them) per relay process: {buffers}")
    assert 33_000 in buffers["LOW"], buffers   # 16,500 B asked, doubled by the kernel (socket(7))
    assert 33_000 not in buffers["HIGH"], buffers
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    # p50 is what the link's rate changes (23-25 ms without it); p99 ranged 9-26 ms over 6 runs of this code on
    # a 2-core VM (and 13-23 ms with the lane code before one retry loop): the tail is the machine's scheduling,
    # so it is only bounded by the link's 50 ms queue
    assert summary["p50_ms"] < 10.0 and summary["p99_ms"] < 50.0, summary
    assert summary["image"] >= 10, summary


def _send_buffers(hosts: Any, relay_pid: int) -> Dict[str, List[int]]:
    """The UDP sockets' send buffers (``ss -m``'s ``tb``) of each child of ``relay_pid``, by the priority it
    exports (its ``--exports-of``)."""
    out = subprocess.run(hosts.run(0, ["ss", "-uapmnH"]), capture_output=True, text=True, timeout=20,
                         check=True).stdout
    sockets = re.sub(r"\n\s+", " ", out).split("\n")   # ss puts skmem on a continuation line
    found: Dict[str, List[int]] = {}
    for pid in _children(relay_pid):
        argv = Path(f"/proc/{pid}/cmdline").read_text().split("\0")
        priority = argv[argv.index("--exports-of") + 1]
        found[priority] = [int(m) for line in sockets if f"pid={pid}," in line
                           for m in re.findall(r"\btb(\d+)", line)]
    return found


def _children(pid: int) -> List[int]:
    """Child processes of ``pid``: every process whose parent (``/proc/N/stat``'s 4th field) it is. Unlike
    ``/proc/pid/task/*/children`` this does not miss a child while the kernel moves it between threads."""
    found: List[int] = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):  # a process that ended meanwhile
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def test_a_killed_priority_process_is_started_again(robots: Tuple[harness.RosMaster, harness.RosMaster],
                                                    spawn: harness.Spawner, tmp_path: Path) -> None:
    """Two masters on loopback. Robot A's relay exports /chatter at HIGH and /slow at LOW (two child processes).
    The HIGH one is killed (SIGKILL, as the OOM killer would): the first process says so, starts it again, and
    B's stock listener gets /robot_a/chatter again."""
    a, b = robots
    (tmp_path / "a.yaml").write_text("graph: robot_a\nexport:\n  /chatter: {transport_priority: HIGH}\n"
                                     "  /slow: {transport_priority: LOW}\n")
    (tmp_path / "b.yaml").write_text("graph: robot_b\nimport:\n  /robot_a/chatter: {}\n")
    spawn(stock_talker("--topic", "/chatter", "--rate", 20, "--count", 0, "--duration", 150), env=a.env)
    spawn(stock_talker("--topic", "/slow", "--rate", 1, "--count", 0, "--duration", 150), env=a.env)
    relay_a = spawn(relay(tmp_path / "a.yaml"), env=a.env, name="relay_a")
    spawn(relay(tmp_path / "b.yaml"), env=b.env, name="relay_b")
    listener = spawn(stock_listener("--topic", "/robot_a/chatter", "--duration", 140), env=b.env)
    listener.wait_for_count("recv", 10, timeout=60)
    harness.wait_until(lambda: len(_children(relay_a.proc.pid)) == 2, 60, interval=0.2,
                       message="relay A's two processes (HIGH and LOW)")
    assert "exited with code" not in relay_a.stderr_tail(200), relay_a.stderr_tail(40)
    children = _children(relay_a.proc.pid)
    high = next(pid for pid in children if "HIGH" in Path(f"/proc/{pid}/cmdline").read_text())
    os.kill(high, signal.SIGKILL)
    harness.wait_until(lambda: high not in _children(relay_a.proc.pid) and len(_children(relay_a.proc.pid)) == 2,
                       60, interval=0.2, message="the HIGH process started again")
    start = len(listener.events("recv"))
    listener.wait_for_count("recv", start + 20, timeout=60)
    assert "exited with code -9" in relay_a.stderr_tail(200), relay_a.stderr_tail(40)
