"""A live micros_rt graph under attack and churn (issue 9, "Robustness, with figures").

Each test runs real processes against the session's rosmaster and prints its figures (pytest -s).
"""

from __future__ import annotations

import math
import random
import string
import struct
import subprocess
import threading
import time
import uuid
from typing import Any, Callable, Dict, List

import pytest

import harness
import micros_rt.transports.dds.offer
from helpers import logs, mrt

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

PROBE = str(harness.PEERS_DIR / "mrt_probe.py")
STRING_MD5 = "992ce8a1687cec8c8bd883ec73ca41d1"
STRING_DDS = "std_msgs::msg::dds_::String_"
UNMATCHED_READER_TIMEOUT = micros_rt.transports.dds.offer.UNMATCHED_READER_TIMEOUT
MAX_PENDING = micros_rt.transports.dds.offer.MAX_PENDING_DDS_OFFERS


def probe(*args: str) -> List[str]:
    return [harness.MICROS_RT_PYTHON, PROBE, *args]


def rss_kb(peer: harness.Peer) -> int:
    """The peer's resident set; a peer that has exited (a zombie has no VmRSS) fails with its stderr."""
    with open(f"/proc/{peer.pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise AssertionError(f"{peer!r} has no VmRSS (exited, returncode {peer.returncode}); last events "
                         f"{peer.events()[-3:]}\nstderr tail:\n{peer.stderr_tail()}")


def dds_links(uri: str, topic: str) -> int:
    return sum(1 for c in harness.node_call(uri, "getBusInfo") if c[4] == topic and c[3] == "DDS")


def no_phantoms(uri: str, topic: str) -> None:
    """Every accepted-but-never-matched DDS offer is dropped within UNMATCHED_READER_TIMEOUT (+ margin)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < UNMATCHED_READER_TIMEOUT + 5:
        left = dds_links(uri, topic)
        if left == 0:
            return
        time.sleep(0.2)
    raise AssertionError(f"{left} phantom DDS connections on {topic} still in getBusInfo "
                         f"{time.monotonic() - t0:.1f} s after the last fake offer "
                         f"(UNMATCHED_READER_TIMEOUT {UNMATCHED_READER_TIMEOUT} s)")


def offer(domain: int, topic: str, reader: str, **overrides: Any) -> List[Any]:
    params: Dict[str, Any] = {"domain": domain, "topic": "rt/" + topic.lstrip("/"), "type": STRING_DDS,
                              "md5": STRING_MD5, "qos": {}, "reader": reader, "participant": str(uuid.uuid4()),
                              "graph": "attacker"}
    params.update(overrides)
    return ["DDS", params]


def test_fake_dds_offers_leave_no_phantom_connections(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                      dds_domain: int) -> None:
    talker = spawn(mrt("talk", "--topic", "/phantom", "--count", "100000", "--rate", "10", "--node-name",
                       "phantom_talker"))
    talker.wait_for("ready", 30)
    uri = harness.lookup_node(ros_master, "/phantom_talker")
    time.sleep(1.0)
    rss0 = rss_kb(talker)
    accepted = 0
    most_at_once = 0
    t_flood = time.monotonic()
    for i in range(300):  # well-formed offers whose readers never appear in DDS discovery
        code, _msg, proto = harness.node_call_raw(uri, "requestTopic", "/phantom",
                                                  [offer(dds_domain, "/phantom", str(uuid.uuid4())), ["TCPROS"]],
                                                  caller_id=f"/fake_{i}")
        assert code == 1, (code, _msg)
        accepted += proto[0] == "DDS"
        if i % 20 == 19:
            most_at_once = max(most_at_once, dds_links(uri, "/phantom"))
    flood_s = time.monotonic() - t_flood
    most_at_once = max(most_at_once, dds_links(uri, "/phantom"))
    assert accepted > 0, "no well-formed DDS offer was accepted at all: the test would prove nothing"
    assert most_at_once <= MAX_PENDING, f"{most_at_once} unmatched DDS links at once (cap {MAX_PENDING})"
    if flood_s < UNMATCHED_READER_TIMEOUT:  # none could have expired yet: the cap bounds the total
        assert accepted <= MAX_PENDING, \
            f"{accepted} of 300 fake offers accepted in {flood_s:.2f} s (cap {MAX_PENDING})"
    slowest = 0.0
    rss_rounds = [rss0]
    for rnd in range(2):
        for i in range(20):  # a megabyte in a field: refused, fast
            t0 = time.monotonic()
            code, _msg, proto = harness.node_call_raw(uri, "requestTopic", "/phantom",
                                                      [offer(dds_domain, "/phantom", "f" * 1_000_000), ["TCPROS"]],
                                                      caller_id=f"/huge_{rnd}_{i}", timeout=10)
            slowest = max(slowest, time.monotonic() - t0)
            assert code == 1 and proto[0] == "TCPROS", f"an offer with a 1 MB reader string got {proto[0]!r}: {_msg}"
        rss_rounds.append(rss_kb(talker))
    no_phantoms(uri, "/phantom")
    rss1, rss2 = rss_rounds[1], rss_rounds[2]
    print(f"\n300 fake offers in {flood_s:.2f} s: {accepted} accepted ({most_at_once} DDS links at once), "
          f"all dropped within {UNMATCHED_READER_TIMEOUT:.0f} s; 2 x 20 offers with a 1 MB reader string: "
          f"slowest answer {slowest:.3f} s; talker RSS {rss0} -> {rss1} -> {rss2} kB")
    assert slowest < 1.0, f"an offer with a 1 MB reader string took {slowest:.2f} s to answer"
    # micros_rt keeps freed large blocks in its heap for the next big message (node.py, _tune_malloc), so the
    # first round may leave the XML-RPC parser's peak resident; kept offers would be 20 MB a round, and a
    # leak grows again on the second round
    assert rss1 - rss0 < 12 * 1024, f"talker RSS grew {rss0} -> {rss1} kB on 20 offers with 1 MB strings"
    assert rss2 - rss1 < 2 * 1024, f"talker RSS grew again {rss1} -> {rss2} kB on 20 more: a leak"
    warnings = [w for w in logs(talker) if "never appeared" in w or "DDS" in w]
    assert 0 < len(warnings) <= 15, warnings  # 5 lines per kind of problem, then counted


def _junk(rng: random.Random, depth: int = 0) -> Any:
    kind = rng.randrange(9 if depth < 2 else 6)
    if kind == 0:
        return rng.randint(-2 ** 31, 2 ** 31 - 1)
    if kind == 1:
        return "".join(rng.choice(string.printable) for _ in range(rng.randint(0, 40)))
    if kind == 2:
        return "x" * rng.choice([300, 5000, 200_000])
    if kind == 3:
        return rng.random() * 1e6
    if kind == 4:
        return rng.random() < 0.5
    if kind == 5:
        return str(uuid.uuid4()) if rng.random() < 0.5 else "not-a-guid"
    if kind == 6:
        return [_junk(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    if kind == 7:
        return {rng.choice(["domain", "topic", "type", "md5", "qos", "reader", "participant", "graph", "zz"]):
                _junk(rng, depth + 1) for _ in range(rng.randint(0, 8))}
    return {"using_best_effort_protocol": _junk(rng, depth + 1), "deadline": _junk(rng, depth + 1)}


def _random_protocols(rng: random.Random, domain: int) -> Any:
    choice = rng.randrange(6)
    if choice == 0:
        return _junk(rng)
    if choice == 1:  # a nearly valid offer with one field broken
        entry = offer(domain, "/abused", str(uuid.uuid4()))
        entry[1][rng.choice(list(entry[1]))] = _junk(rng)
        return [entry, ["TCPROS"]] if rng.random() < 0.5 else [entry]
    if choice == 2:
        return [["UDPROS"], ["SHM", 1, 2], [rng.choice(["DDS", "TCPROS", "XYZ"]), _junk(rng)]]
    if choice == 3:
        return [offer(domain, "/abused", "bad guid " + str(rng.random()))]
    if choice == 4:
        return [[_junk(rng)] for _ in range(rng.randint(0, 20))]
    return [offer(domain, "/abused", str(uuid.uuid4()), qos={"deadline": "soon"}), ["TCPROS"]]


def test_ten_thousand_random_request_topic_calls(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                 dds_domain: int) -> None:
    talker = spawn(mrt("talk", "--topic", "/abused", "--count", "100000", "--rate", "10", "--node-name",
                       "abused_talker"))
    talker.wait_for("ready", 30)
    uri = harness.lookup_node(ros_master, "/abused_talker")
    time.sleep(1.0)
    rss_start = rss_kb(talker)
    counts = {"answered": 0, "errors": 0}
    lock = threading.Lock()

    def attack(seed: int, n: int) -> None:
        rng = random.Random(seed)
        for i in range(n):
            topic = rng.choice(["/abused", "/abused", "/nonexistent", "", "x" * 1000, "/abused/../x"])
            try:
                harness.node_call_raw(uri, "requestTopic", topic, _random_protocols(rng, dds_domain),
                                      caller_id=rng.choice(["/attacker", f"/attacker_{seed}", "/a" * 300]))
                with lock:
                    counts["answered"] += 1
            except Exception:  # a Fault for a broken call is an answer too, as long as the node lives
                with lock:
                    counts["errors"] += 1

    def volley(seeds: range, per_thread: int) -> float:
        t0 = time.monotonic()
        threads = [threading.Thread(target=attack, args=(seed, per_thread)) for seed in seeds]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=240)
        return time.monotonic() - t0

    # Warm-up: rospy's XML-RPC server answers each call on a new thread and the allocator keeps the
    # high-water mark of the first burst (a stock rospy talker grows 15-20 MB on the same 10,000 calls);
    # what must not happen is growth that goes on with the calls: the second 10,000 are measured.
    attack_start = time.monotonic()
    volley(range(100, 104), 2500)
    rss0 = rss_kb(talker)
    counts.update(answered=0, errors=0)
    elapsed = volley(range(4), 2500)
    assert sum(counts.values()) == 10_000, counts
    assert talker.alive(), talker.stderr_tail()
    no_phantoms(uri, "/abused")
    rss1 = rss_kb(talker)
    negotiation_warnings = [w for w in logs(talker) if "DDS" in w or "protocol" in w or "offer" in w]
    # the limiter's promise is per 30-s interval (a few first lines per kind of problem, one summary per caller
    # and kind), so a loaded machine that stretches the attack over more intervals may log more; unlimited,
    # the 20,000 calls would log thousands of lines
    intervals = math.ceil((time.monotonic() - attack_start) / 30.0)
    print(f"\n10,000 random requestTopic calls in {elapsed:.1f} s ({10_000 / elapsed:.0f}/s): {counts}; talker RSS "
          f"{rss_start} kB at start, {rss0} kB after a first 10,000 (warm-up), {rss1} kB after the next 10,000; "
          f"{len(negotiation_warnings)} WARN lines from the negotiation over {intervals} 30-s intervals")
    assert rss1 - rss0 < 5 * 1024, f"talker RSS grew {rss0} -> {rss1} kB over 10,000 calls after warm-up"
    assert len(negotiation_warnings) <= 40 * intervals, (len(negotiation_warnings), negotiation_warnings[:50])
    # and it still serves: a stock tool over TCPROS, a micros_rt listener over DDS
    cp = harness.rostopic(ros_master, "echo", "-n", "3", "/abused", timeout=30)
    assert "hello" in cp.stdout, cp.stdout
    listener = spawn(mrt("listen", "--topic", "/abused", "--duration", "20"))
    listener.wait_for_count("recv", 3, timeout=30)
    assert {e["transport"] for e in listener.events("recv")} == {"DDS"}


GARBAGE_WRITER = """
import os, random, struct, sys, time
from cyclonedds._clayer import ddspy_write
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from std_msgs.msg import String
from sensor_msgs.msg import LaserScan
from micros_rt.transports.dds.types import dds_type_for

rng = random.Random(7)
dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
kind, topic, n_bad = sys.argv[1], sys.argv[2], int(sys.argv[3])
cls = String if kind == "string" else LaserScan
t = dds_type_for(cls)
writer = DataWriter(dp, Topic(dp, "rt/" + topic.lstrip("/"), t.idl_class))
deadline = time.monotonic() + 15
while not writer.get_matched_subscriptions() and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.5)
valid = bytes(t.encode(String(data="template") if cls is String else LaserScan(ranges=[1.0] * 50)))
good = 0
for i in range(n_bad):
    b = bytearray(valid)
    r = rng.random()
    if r < 0.3:
        b = b[:rng.randrange(4, len(b))]
    elif r < 0.6:
        for _ in range(rng.randint(1, 6)):
            b[rng.randrange(4, len(b))] ^= 1 << rng.randrange(8)
    elif r < 0.8:
        off = 4 + 4 * rng.randrange((len(b) - 4) // 4)
        b[off:off + 4] = b"\\xff\\xff\\xff\\xff"
    else:
        b = bytearray(b"\\x00\\x01\\x00\\x00" + rng.randbytes(rng.randint(0, 40)))
    ddspy_write(writer._ref, bytes(b))
    if i % 10 == 0:
        msg = String(data=f"good {good}") if cls is String else LaserScan(ranges=[float(good)] * 50)
        ddspy_write(writer._ref, t.encode(msg))
        good += 1
    time.sleep(0.002)
time.sleep(1.0)
print(good, flush=True)
"""


def test_fuzzed_dds_samples_on_a_live_topic(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    for kind, topic, type_ in (("string", "/fuzzed", "std_msgs/String"), ("scan", "/fuzzed_scan",
                                                                         "sensor_msgs/LaserScan")):
        listener = spawn(probe("listen", "--topic", topic, "--type", type_, "--duration", "40"))
        listener.wait_for("ready", 30)
        cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", GARBAGE_WRITER, kind, topic, "1000"],
                            env=ros_master.env, capture_output=True, text=True, timeout=90)
        assert cp.returncode == 0, cp.stderr[-2000:]
        good = int(cp.stdout.split()[-1])
        # a mutated sample can still be a valid encoding (a flipped bit in a float): delivered is
        # at least the good ones, and everything else is counted as malformed, nothing vanishes
        status = harness.wait_until(
            lambda: next((e for e in reversed(listener.events("status"))
                          if e["delivered"] + e["malformed"] >= good + 1), None), 15, message="samples accounted for")
        print(f"\n{topic}: 1000 mutated/random samples + {good} good ones: delivered {status['delivered']}, "
              f"malformed {status['malformed']}, received {status['received']}")
        # Cyclone itself discards some broken samples (e.g. truncated below the CDR header) before any
        # reader, and a flipped bit in a float is still a valid sample: what reaches us is accounted for
        assert status["delivered"] >= good, status
        if kind == "string":
            assert status["malformed"] >= 50, status
        assert status["delivered"] + status["malformed"] == status["received"], status
        if kind == "string":
            got = [e["data"] for e in listener.events("recv")]
            assert [f"good {i}" for i in range(good)] == [g for g in got if g.startswith("good ")], got[:20]
        warned = [w for w in logs(listener) if "malformed" in w]
        assert len(warned) <= 1, warned
        assert listener.alive()


def test_thousand_endpoint_cycles_return_threads_fds_and_entities(ros_master: harness.RosMaster,
                                                                  spawn: harness.Spawner) -> None:
    churn = spawn(probe("churn", "--cycles", "1000"))
    start = churn.wait_for(lambda e: e.get("event") == "state" and e.get("at") == "start", 60)
    warm = churn.wait_for(lambda e: e.get("event") == "state" and e.get("at") == "warm", 120)
    end = churn.wait_for(lambda e: e.get("event") == "state" and e.get("at") == "end", 300)
    print(f"\n1,000 advertise/unregister + 1,000 subscribe/unregister cycles: start {start}, after 100 {warm}, "
          f"end {end}")
    assert end["entities"] == start["entities"], (start, end)
    for key in ("threads", "tasks", "fds"):  # an XML-RPC request or the master probe may be in flight
        assert end[key] <= start[key] + 2, (key, start, end)
    assert end["rss_kb"] - warm["rss_kb"] < 5 * 1024, (warm, end)


def test_hundred_publisher_restarts_keep_the_subscriber_small(ros_master: harness.RosMaster,
                                                              spawn: harness.Spawner) -> None:
    listener = spawn(probe("listen", "--topic", "/restarted", "--duration", "120"))
    listener.wait_for("ready", 30)
    for k in range(5):  # real process restarts
        proc = spawn(probe("restarts", "--topic", "/restarted", "--count", "1"))
        proc.wait_for("done", 30)
        proc.wait(30)
    publisher = spawn(probe("restarts", "--topic", "/restarted", "--count", "100"))
    after10 = None
    def restarted(i: int) -> Callable[[Dict[str, Any]], bool]:
        return lambda e: e.get("event") == "restarted" and e.get("i") == i

    for i in range(100):
        publisher.wait_for(restarted(i), 30)
        if i == 9:
            time.sleep(0.6)
            after10 = listener.events("status")[-1]
    publisher.wait_for("done", 30)
    # the last writer is gone: housekeeping forgets its state within a few rounds; a publisher killed after
    # its negotiation but before the subscriber discovered its DDS writer (a loaded machine: CI saw it once)
    # is given the 30 s a never-discovered writer gets before it is dropped with a warning
    final = harness.wait_until(lambda: next((e for e in listener.events("status")[-1:] if e["writers"] <= 1), None),
                               45, interval=0.2, message="per-writer state back to at most one writer")
    got = [e["data"] for e in listener.events("recv")]
    print(f"\n105 publisher restarts: {len(got)} messages; subscriber after 10: rss {after10 and after10['rss_kb']} "
          f"kB, writers {after10 and after10['writers']}; at the end: rss {final['rss_kb']} kB, writers "
          f"{final['writers']}")
    assert after10 is not None
    assert final["writers"] <= 1, final
    assert final["rss_kb"] - after10["rss_kb"] < 5 * 1024, (after10, final)
    assert len(got) >= 100, len(got)


def test_lossless_publisher_outlives_subscribers_killed_one_after_another(ros_master: harness.RosMaster,
                                                                          spawn: harness.Spawner) -> None:
    # micros_rt's own loopback configuration (no CYCLONEDDS_URI): a 100 Hz queue_size=None talker, and
    # subscribers killed (SIGKILL) one after another, each while the previous one's lease still runs. With
    # Cyclone's adaptive writer window, every dead subscriber's retransmissions shrank the talker's window, and
    # the 15th-16th newcomer heard nothing while publish() blocked until PublishTimeoutError
    env = {k: v for k, v in ros_master.env.items() if k != "CYCLONEDDS_URI"}
    env["ROS_IP"] = "127.0.0.1"
    talker = spawn(mrt("talk", "--topic", "/churn", "--queue-size", 0, "--count", 100000, "--rate", 100,
                       "--node-name", "churn_talker"), env=env)
    talker.wait_for("ready", 30)
    # the listeners announce a 5 s lease, so a dead one is still retransmitted to when the next ones come,
    # however slowly this machine starts them
    listener_env = dict(env, MICROS_RT_LEASE_DURATION="5")
    for i in range(24):
        listener = spawn(mrt("listen", "--topic", "/churn", "--duration", 60, "--node-name", f"churn_{i}"),
                         env=listener_env)
        try:
            listener.wait_for("recv", 15)  # every newcomer hears the talker, over DDS
        except AssertionError:  # what the talker said is what tells a negotiation problem from a stalled writer
            print(f"talker's last events {talker.events()[-3:]}\ntalker's log {logs(talker)[-30:]}\n"
                  f"listener's log {logs(listener)[-30:]}")
            raise
        assert listener.events("recv")[0]["transport"] == "DDS"
        listener.proc.kill()  # no goodbye: its DDS reader stays matched until the lease ends
        listener.proc.wait(10)
        time.sleep(0.3)
        assert talker.alive(), talker.stderr_tail()
    final = spawn(mrt("listen", "--topic", "/churn", "--duration", 60, "--node-name", "churn_last"), env=listener_env)
    final.wait_for_count("recv", 100, timeout=15)
    assert talker.alive(), talker.stderr_tail()  # a PublishTimeoutError would have ended it
