"""A control topic and a camera sharing a constrained link: two namespace hosts, the publisher's egress
shaped by a real `tc tbf` qdisc to 40 Mbit/s with a 50 ms queue (a radio link's bottleneck), one publisher
process with a 1 kHz HIGH control topic and a 30 Hz 640x480 LOW camera (about 221 Mbit/s of demand).

The camera's datagrams fill the socket faster than the link drains it. Before lanes, Cyclone waited inside
its write (for socket room, for acknowledgements) holding Python's GIL, and every thread of the process
stood still: the control loop published 2-30 % of its messages. Now the camera waits in its own lane,
without the GIL, and in a socket of its own: its writer is on a participant for LOW, whose sockets are marked
CS1, while the control topic's are marked AF41.
"""

from __future__ import annotations

import collections
import re
import signal
import subprocess
from typing import Any, Dict, Iterator, List, NamedTuple, Optional

import pytest

import harness
from netns import Hosts

LINK = str(harness.PEERS_DIR / "mrt_link.py")
SECONDS = 6.0
#: The control topic's latency (ms) when the camera's traffic is kept out of the link's 50 ms queue (paced by the
#: link's rate in a profile, or served after the control topic by a DSCP-honouring link), on 2 cores with the
#: camera, tcpdump and both hosts' nodes sharing them. The tail is mostly the subscriber's GIL, held decoding
#: 921 kB frames: p99 3.7-19.1 ms over 8 runs, and 26.2 ms once in a full suite run (p50 4.6 ms). A queue that
#: fills moves the whole distribution instead: with the camera unpaced, p50 21.8-22.2, p90 27.6-28.1, p99 34-39 ms;
#: paced, p50 3.6-3.7, p90 4.8, p99 5.7-6.1 (2 runs each). So the bound is on the 90th percentile, which tells the
#: two apart by 5x, and the 99th only has to stay inside the link's queue. The benchmark
#: (benchmarks/constrained_link.py) measures the difference; the mechanism (the pacing rate, the DSCP marks) is
#: asserted itself.
PACED_P90_MS = 12.0
PACED_P99_MS = 50.0
#: the camera over paced TCPROS: its segments still share the link's queue in bursts (p50 5.7, p90 11.0, p99 22.0 ms
#: once; unpaced p90 20.9, p99 44.4). Its p99 bound of before (25 ms) was 1.1x what was seen, a scheduling hiccup
#: away from failing on a loaded machine; the 90th percentile tells paced from unpaced with room on both sides
PACED_TCP_P90_MS = 16.0


def kept_out_of_the_queue(summary: Dict[str, Any], *, p90_ms: Optional[float] = PACED_P90_MS,
                          p99_ms: float = PACED_P99_MS) -> None:
    assert (p90_ms is None or p90(summary) < p90_ms) and summary["p99_ms"] < p99_ms, \
        (p90(summary), {k: v for k, v in summary.items() if k != "control_cdf_ms"})


def link(*args: Any) -> List[str]:
    return [harness.MICROS_RT_PYTHON, LINK, *[str(a) for a in args]]


@pytest.fixture
def shaped_pair(dds_domain: int) -> Iterator[Hosts]:
    hosts = Hosts(2)
    try:
        hosts.up()
        # the publisher host's egress: 40 Mbit/s, a 50 ms queue (tbf), as a radio link's bottleneck
        hosts.sh("ip", "netns", "exec", hosts.names[0], "tc", "qdisc", "add", "dev", hosts.link_name(0), "root",
                 "tbf", "rate", "40mbit", "burst", "32kbit", "latency", "50ms")
        yield hosts
    finally:
        hosts.down()


@pytest.fixture
def dscp_pair(dds_domain: int) -> Iterator[Hosts]:
    hosts = Hosts(2)
    try:
        hosts.up()
        hosts.shape_htb_dscp(0)  # the publisher host's egress: 40 Mbit/s, AF4x/EF/CS5-7 served first
        yield hosts
    finally:
        hosts.down()


def capture_marks(capture: "subprocess.Popen[str]") -> "collections.Counter[Any]":
    """What tcpdump saw leave a host, counted by (TOS byte, protocol); called once the publisher is done, so the
    capture stops now (it used to wait 30 s for a packet count a short run never reaches)."""
    if capture.poll() is None:
        capture.send_signal(signal.SIGINT)  # `ip netns exec` runs tcpdump itself: it prints what it has and exits
    try:
        dump, _ = capture.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        capture.kill()
        dump, _ = capture.communicate()
    marks = collections.Counter(re.findall(r"\(tos (0x[0-9a-f]+),.*? proto (\w+) ", dump))
    print(f"\npackets from the publisher's host by (TOS, protocol), of {sum(marks.values())} captured: {dict(marks)}")
    return marks


def start_capture(hosts: Hosts, count: int = 3000) -> "subprocess.Popen[str]":
    """tcpdump of what leaves host 0 (IP header and all), at most ``count`` packets."""
    return subprocess.Popen(hosts.run(0, ["tcpdump", "-i", hosts.link_name(0), "-nn", "-v", "-l", "-c", str(count),
                                          "src", "host", hosts.ip(0)]),
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)


def p90(summary: Dict[str, Any]) -> float:
    """The control topic's 90th percentile latency (ms), from the subscriber's 200-point distribution."""
    cdf = summary.get("control_cdf_ms") or [float("inf")]
    return float(cdf[min(len(cdf) - 1, 180)])


class Run(NamedTuple):
    ready: Dict[str, Any]      # the publisher's 'ready' event
    published: Dict[str, Any]  # its 'published' event: counts, statistics, links
    summary: Dict[str, Any]    # the subscriber's 'summary' event: counts, control latency, transports
    marks: "collections.Counter[Any]"  # what left host 0, by (TOS, protocol); empty without a capture


def run_pair(hosts: Hosts, spawn: harness.Spawner, label: str, *, pub_env: Optional[Dict[str, str]] = None,
             sub_env: Optional[Dict[str, str]] = None, capture: bool = False) -> Run:
    """The subscriber on host 1, then the publisher on host 0 for SECONDS (with tcpdump on host 0's link when
    ``capture``); prints what crossed, under ``label``."""
    sub = spawn(hosts.run(1, link("sub", "--seconds", 90)), env={**hosts.env(1), **(sub_env or {})}, name="sub")
    sub.wait_for("ready", 60)
    dump = start_capture(hosts) if capture else None
    # the 1 kHz loop catches up stalls of up to 20 ms (the camera thread's GIL, a loaded machine): what it
    # publishes then measures publish() blocking, not the scheduler (see mrt_link.paced)
    pub = spawn(hosts.run(0, link("pub", "--seconds", SECONDS, "--catch-up", 0.02)), env={**hosts.env(0), **(pub_env or {})}, name="pub")
    ready = pub.wait_for("ready", 90)
    published = pub.wait_for("published", SECONDS + 90)
    summary = sub.wait_for("summary", 120)
    marks = capture_marks(dump) if dump is not None else collections.Counter()
    print(f"\n40 Mbit/s {label}: control published {published['control']} of {published['intended_control']}, "
          f"delivered {summary['control']} (p50 {summary['p50_ms']:.1f} ms, p90 {p90(summary):.1f} ms, p99 "
          f"{summary['p99_ms']:.1f} ms); images "
          f"published {published['image']}, delivered {summary['image']}; publisher statistics "
          f"{published['statistics']}; links {published['links']}")
    return Run(ready, published, summary, marks)


def profile_env(path: Any, text: str) -> Dict[str, str]:
    path.write_text(text)
    return {"MICROS_RT_QOS_PROFILE": str(path)}


def test_two_dds_topics_of_one_process_leave_with_their_own_dscp_and_the_link_serves_control_first(
        dscp_pair: Hosts, spawn: harness.Spawner) -> None:
    # One process, both topics on DDS: the HIGH control topic's writer is on the process participant, the
    # LOW camera's on a participant of its own (its own sockets, marked CS1+); Cyclone sends all of one
    # participant's data through one socket, so before this both left marked AF41 and the DSCP-honouring
    # link served the camera as urgently as the control topic (benchmark: control p99 121-124 ms).
    published, summary, marks = run_pair(dscp_pair, spawn, "htb link (DSCP honoured), both topics on DDS",
                                         capture=True)[1:]
    classes = dscp_pair.class_bytes(0)
    print(f"bytes per htb class {classes}")
    assert summary["transports"] == ["DDS"] and summary["image_transports"] == ["DDS"], summary
    # two DSCP values from one process's DDS datagrams: the control topic AF41 (0x88), the camera CS1+ (0x28)
    assert marks[("0x88", "UDP")] >= 20 and marks[("0x28", "UDP")] >= 100, marks
    assert marks[("0x88", "TCP")] == 0 and marks[("0x28", "TCP")] == 0, marks
    # the link's priority class carried the control topic (and discovery), the default class the camera
    assert classes.get("1:20", 0) > 4 * classes.get("1:10", 0) > 0, classes
    assert published["control"] >= 0.9 * published["intended_control"], published
    control = published["statistics"]["control"]
    assert summary["control"] + control["dropped"] >= published["control"] - 1, (summary, control)
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    # the camera never delays the control topic in the sender's socket nor in the link's queue (p99 0.5-4.8 ms;
    # 16 ms once beside another test run; both marked AF41, the benchmark's control p99 was 121-124 ms)
    kept_out_of_the_queue(summary)
    assert summary["image"] >= 10, summary


def test_a_busy_low_camera_does_not_throttle_a_high_control_topic(shaped_pair: Hosts,
                                                                 spawn: harness.Spawner) -> None:
    ready, published, summary, _ = run_pair(shaped_pair, spawn, "tbf link, control HIGH 1 kHz + camera LOW "
                                            "640x480 30 Hz in one process")
    assert ready["control"] >= 1 and ready["image"] >= 1, ready
    share = published["control"] / published["intended_control"]
    assert summary["transports"] == ["DDS"], summary
    # before lanes: 2-30 % (the 2,699 of 10,000; 117 of 6,000 here); 99.9 % measured now
    assert share >= 0.9, published
    # The camera's writer is on a participant of its own (LOW), so its fragments no longer fill the socket the
    # control topic is sent through: 5,995 of 5,995 delivered (p99 28 ms, the link's 50 ms FIFO queue). When both
    # shared one socket, the control topic's lane superseded 5-11 % of it while the camera filled that socket
    # (89.7 % delivered in a CI run). Whatever is not delivered is counted, never lost silently.
    control = published["statistics"]["control"]
    assert summary["control"] + control["dropped"] >= published["control"] - 1, (summary, control)
    assert summary["control"] >= 0.95 * published["control"], (summary, published)
    # the camera's publish() never waits for the link: every frame is published, those superseded before
    # the link had room are counted, not sent; the newest still cross (rospy: ~5 per second here)
    image = published["statistics"]["image"]
    assert published["image"] >= 0.8 * 30 * SECONDS and image["blocked_seconds"] < 1.0, published
    assert summary["image"] >= 10 and image["dropped"] > 0, (summary, image)
    # (+1: a frame given up while its datagrams were already leaving still arrives after the snapshot)
    assert summary["image"] + image["dropped"] <= published["image"] + 1, (summary, image)


def test_the_links_rate_in_the_publishers_profile_keeps_dds_control_within_milliseconds_on_a_fifo_link(
        shaped_pair: Hosts, spawn: harness.Spawner, tmp_path: Any) -> None:
    # Both topics on DDS, a FIFO link (nothing tells the packets apart): the camera's datagrams fill the link's
    # 50 ms queue and the control topic waits behind them (the test above: p99 ~28 ms). Told the link's rate,
    # the camera's participant (LOW, a socket of its own) gets a 16.5 kB send buffer: a datagram in the link's
    # queue counts against it, so the camera never has more than ~33 kB (6.6 ms) queued there.
    pub_env = profile_env(tmp_path / "pub.yaml",
                          f"links:\n  radio: {{peers: [{shaped_pair.ip(1)}], bandwidth: 40Mbit}}\n")
    published, summary = run_pair(shaped_pair, spawn, "tbf link, both topics on DDS, the link's rate in the "
                                  "publisher's profile", pub_env=pub_env)[1:3]
    assert summary["transports"] == ["DDS"] and summary["image_transports"] == ["DDS"], summary
    assert published["control"] >= 0.9 * published["intended_control"], published
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    # benchmark: p99 4.9-5.2 ms (rospy 39-57 ms; without the link's rate 28 ms); see PACED_P90_MS
    kept_out_of_the_queue(summary)
    assert summary["image"] >= 10, summary


def test_a_profile_sends_the_camera_over_tcp_and_the_control_topic_keeps_its_latency(
        shaped_pair: Hosts, spawn: harness.Spawner, tmp_path: Any) -> None:
    # The camera's DDS datagrams (no congestion control) keep the link's queue full, and the HIGH control
    # topic waits behind them (the all-DDS test: p50 ~21 ms, p99 ~28 ms). A subscriber profile that has the
    # camera offered over TCPROS first leaves the queue to TCP's congestion window; control stays on DDS.
    sub_env = profile_env(tmp_path / "sub.yaml", "subscribers:\n  /image: {transport_hints: [TCPROS]}\n")
    published, summary = run_pair(shaped_pair, spawn, "tbf link, camera over TCPROS by profile", sub_env=sub_env)[1:3]
    assert summary["transports"] == ["DDS"] and summary["image_transports"] == ["TCPROS"], summary
    assert published["control"] >= 0.9 * published["intended_control"], published
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    # measured 3.5-3.6 ms (p99 30-45 ms); the camera on DDS: 21 ms (p99 ~28 ms)
    assert summary["p50_ms"] < 15.0, summary
    assert summary["image"] >= 10, summary


def test_a_link_in_the_publishers_profile_paces_the_camera_and_control_keeps_milliseconds(
        shaped_pair: Hosts, spawn: harness.Spawner, tmp_path: Any) -> None:
    # The camera over TCPROS (the test above) still fills the link's 50 ms queue: TCP grows its window until
    # a packet is lost, and control's datagrams wait behind the queue (p99 30-41 ms). The publisher's profile
    # names the link and its rate: the camera's TCP connection is paced below it (SO_MAX_PACING_RATE), the
    # queue stays short, and the control topic's tail is the link's serialisation, not its queue.
    # The sending robot's profile alone does it: its camera is served over TCPROS only (no DDS writer, so the
    # subscriber's DDS reader, there for the control topic's sake too, is matched by nothing on /image).
    pub_env = profile_env(tmp_path / "pub.yaml", "publishers:\n  /image: {transport_hints: [TCPROS]}\n"
                          f"links:\n  radio: {{peers: [{shaped_pair.ip(1)}], bandwidth: 40Mbit}}\n")
    # what leaves the publisher's host, IP header and all: each topic's packets carry its own DSCP
    published, summary, marks = run_pair(shaped_pair, spawn, "tbf link, camera over TCPROS paced by the "
                                         "publisher's profile", pub_env=pub_env, capture=True)[1:]
    # one process, two DSCP values: the HIGH control topic's DDS datagrams AF41 (0x88), the LOW camera's
    # TCPROS segments CS1+ (0x28); Cyclone alone would have marked both 0x88
    # (tcpdump prints each packet and the kernel drops what it cannot keep up with: a sample, 1,283 of the first
    # ~3 s here, 303 and 939 of them the two topics')
    assert marks[("0x88", "UDP")] >= 20 and marks[("0x28", "TCP")] >= 100, marks
    assert marks[("0x28", "UDP")] == 0 and marks[("0x88", "TCP")] == 0, marks
    assert summary["transports"] == ["DDS"] and summary["image_transports"] == ["TCPROS"], summary
    # the camera's one connection, to the subscriber's host, was paced below 36 Mbit/s (90 % of the link)
    (radio,) = published["links"]
    (camera,) = radio["connections"]
    assert camera["topic"] == "/image" and camera["peer"] == shaped_pair.ip(1), radio
    assert 1e6 < camera["rate_bps"] <= 36e6 + 1, radio
    assert published["control"] >= 0.9 * published["intended_control"], published
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    kept_out_of_the_queue(summary, p90_ms=PACED_TCP_P90_MS)
    assert summary["image"] >= 10, summary
