"""Every QoS option has an effect one can measure between separate processes, on DDS and, where the
subscriber can enforce it, on a TCPROS link. See docs/qos.md for the table.

Tolerances are for a loaded 2-core machine; each test fails if the option is ignored.
"""

from __future__ import annotations

import re
import subprocess
import time
from typing import Any, List

import pytest

import harness
from helpers import logs, mrt, received, stock_talker, tcp_links_between, transports

import micros_rt
from micros_rt.exceptions import UnsupportedQoSError

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)


def _recv_times(peer: harness.Peer) -> List[float]:
    return [float(e["t"]) for e in peer.events("recv")]


# ---------------------------------------------------------------------------
# 1. time_filter_duration


def _assert_about_one_per_second(times: List[float], sent: int) -> None:
    span = times[-1] - times[0] if len(times) > 1 else 0.0
    # 50 Hz for ~4 s: unfiltered that is ~200 messages; with a 1 s filter about 4-5.
    assert sent >= 150, sent
    assert 3 <= len(times) <= 7, (len(times), times)
    gaps = [b - a for a, b in zip(times, times[1:])]
    print(f"time filter: {len(times)} of {sent} delivered, gaps {[round(g, 2) for g in gaps]}")
    assert min(gaps) >= 0.8, gaps  # never two deliveries within the filter window (20 ms jitter allowed)
    assert span <= 6.0


def test_time_filter_on_dds(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/qf_dds", "--duration", "12",
                         qos={"time_filter_duration": 1.0}))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/qf_dds", "--count", "200", "--rate", "50",
                       "--wait-subscribers", "1", "--linger", "0.5"))
    talker.wait_for("done", 20)
    time.sleep(0.3)
    assert set(transports(listener)) == {"DDS"}
    _assert_about_one_per_second(_recv_times(listener), talker.count("sent"))


def test_time_filter_on_tcpros_from_stock_talker(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/qf_tcp", "--duration", "12",
                         qos={"time_filter_duration": 1.0}))
    listener.wait_for("ready", 30)
    talker = spawn(stock_talker("--topic", "/qf_tcp", "--count", "200", "--rate", "50",
                                "--wait-subscribers", "1", "--linger", "0.5"))
    talker.wait_for("done", 20)
    time.sleep(0.3)
    assert set(transports(listener)) == {"TCPROS"}
    _assert_about_one_per_second(_recv_times(listener), talker.count("sent"))


# ---------------------------------------------------------------------------
# 2. deadline + deadline_cb


def _deadline_phases(listener: harness.Peer) -> tuple[int, int, int]:
    """Deadline events before the first message, while messages flow, and in the 1 s after the last one."""
    recv = listener.events("recv")
    first, last = recv[0]["_rx"], recv[-1]["_rx"]
    dl = [e["_rx"] for e in listener.events("deadline")]
    before = sum(1 for t in dl if t < first)
    during = sum(1 for t in dl if first < t < last)
    after = sum(1 for t in dl if last < t <= last + 1.0)
    return before, during, after


@pytest.mark.parametrize("kind", ["dds", "tcpros"])
def test_deadline_fires_in_silence_and_stops_while_messages_flow(ros_master: harness.RosMaster,
                                                                  spawn: harness.Spawner, kind: str) -> None:
    topic = f"/qdl_{kind}"
    # the listener's window outlasts the talker's start-up on a loaded machine; the phases are read by time
    listener = spawn(mrt("listen", "--topic", topic, "--duration", "40", "--deadline-events",
                         qos={"deadline": 0.2}))
    listener.wait_for("ready", 30)
    time.sleep(1.0)  # silence: ~5 deadline periods
    if kind == "dds":
        talker = spawn(mrt("talk", "--topic", topic, "--count", "60", "--rate", "30",
                           "--wait-subscribers", "1", "--linger", "3"))
    else:
        talker = spawn(stock_talker("--topic", topic, "--count", "60", "--rate", "30",
                                    "--wait-subscribers", "1", "--linger", "3"))
    talker.wait_for("done", 30)
    last = listener.events("recv")[-1]["_rx"]  # silence again: wait for a deadline past the 1 s after it
    listener.wait_for(lambda e: e.get("event") == "deadline" and e["_rx"] > last + 1.2, 20)
    assert set(transports(listener)) == {"DDS" if kind == "dds" else "TCPROS"}
    assert listener.count("recv") >= 55
    before, during, after = _deadline_phases(listener)
    print(f"deadline {kind}: before={before} during={during} after(1 s)={after}")
    # 30 Hz = 33 ms gaps, far inside the 0.2 s deadline: nothing fires while data flows
    assert during == 0, listener.events("deadline")
    assert before >= 3, before
    assert 3 <= after <= 6, after  # 1 s of silence / 0.2 s deadline = 5
    totals = [e["total"] for e in listener.events("deadline")]
    assert totals == list(range(1, len(totals) + 1))


# ---------------------------------------------------------------------------
# 3. msg_valid_period (Lifespan)


def _lifespan_run(spawn: harness.Spawner, topic: str, talker_qos: dict[str, Any]) -> tuple[harness.Peer, int]:
    # A slow subscriber (0.1 s per callback) behind a 40 msg burst at 40 Hz: message i waits ~0.075*i s.
    listener = spawn(mrt("listen", "--topic", topic, "--duration", "30", "--queue-size", "100",
                         "--callback-sleep", "0.1", "--exit-after", "40",
                         qos={"ordered_by_sending_timestamp": False}))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", topic, "--count", "40", "--rate", "40", "--wait-subscribers", "1",
                       "--linger", "1", qos=talker_qos))
    talker.wait_for("done", 30)
    sent = talker.count("sent")
    # with a lifespan the expired messages never come and --exit-after is not reached: once nothing has come for
    # 1.5 s (the slow callback takes 0.1 s per message), the listener is stopped and says "done" as it ends
    harness.wait_still(lambda: (listener.count("recv"), listener.count("done")), 1.5, 30)
    if not listener.events("done"):
        listener.stop()
    listener.wait_for("done", 35)
    return listener, sent


def test_slow_subscriber_without_lifespan_gets_everything_late(ros_master: harness.RosMaster,
                                                                spawn: harness.Spawner) -> None:
    # the control for the next test: the same run without msg_valid_period
    control, sent = _lifespan_run(spawn, "/qls_control", {})
    assert len(received(control)) == sent == 40
    assert control.events("done")[0]["latency"]["max"] > 1.5


def test_msg_valid_period_drops_messages_that_wait_too_long_on_dds(ros_master: harness.RosMaster,
                                                                    spawn: harness.Spawner) -> None:
    listener, sent = _lifespan_run(spawn, "/qls_dds", {"msg_valid_period": 0.5})
    got = received(listener)
    assert sent == 40
    assert set(transports(listener)) == {"DDS"}
    done = listener.events("done")[0]
    print(f"lifespan: {len(got)} of {sent} delivered, max age {done['latency']['max']:.3f} s")
    # the burst lasts 1 s, messages older than 0.5 s expire: ~15 of 40 delivered at 10/s
    assert 5 <= len(got) <= 25, got
    assert done["latency"]["max"] < 0.5 + 0.1, done["latency"]
    nums = [int(x.split()[1]) for x in got]
    assert nums[0] == 0 and nums == sorted(nums)


# ---------------------------------------------------------------------------
# 4. latency statistics and latency_budget misses


def test_latency_statistics_within_budget(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    # fast subscriber, generous budget: no misses, sub-50 ms latencies
    fast = spawn(mrt("listen", "--topic", "/qlat_fast", "--duration", "30", "--queue-size", "100",
                     "--exit-after", "60"))
    fast.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/qlat_fast", "--count", "60", "--rate", "30", "--wait-subscribers", "1",
              qos={"latency_budget": 0.25}))
    s = fast.wait_for("done", 40)["latency"]
    assert s["count"] == len(received(fast)) >= 55
    assert 0 < s["p50"] <= s["p99"] <= s["max"]
    assert s["p50"] < 0.05, s
    print(f"latency fast: {s}")
    assert s["budget_checked"] == s["count"] and s["budget_misses"] == 0, s


def test_latency_budget_misses_are_counted_and_logged(ros_master: harness.RosMaster,
                                                      spawn: harness.Spawner) -> None:
    # slow subscriber (queueing), 50 ms budget: most messages miss it, each one counted
    slow = spawn(mrt("listen", "--topic", "/qlat_slow", "--duration", "30", "--queue-size", "100",
                     "--callback-sleep", "0.05", "--log-debug", "--exit-after", "40"))
    slow.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/qlat_slow", "--count", "40", "--rate", "40", "--wait-subscribers", "1",
              qos={"latency_budget": 0.05}))
    s = slow.wait_for("done", 40)["latency"]
    assert s["count"] == 40
    print(f"latency slow: {s}")
    assert s["budget_misses"] >= 20, s
    assert s["max"] > 0.3
    debug = logs(slow, "DEBUG")
    assert sum("latency_budget" in t for t in debug) == s["budget_misses"], debug[:3]


# ---------------------------------------------------------------------------
# 5. ordered_by_sending_timestamp and lagging clocks


@pytest.mark.parametrize("by_source", [True, False])
def test_destination_order_with_interleaved_source_stamps(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                          by_source: bool) -> None:
    topic = f"/qord_{'src' if by_source else 'rcv'}"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", "40", "--queue-size", "1000",
                         qos={"ordered_by_sending_timestamp": by_source}))
    listener.wait_for("ready", 30)
    # "late" stamps its samples 0.3 s in the past: each of its samples is older than the last "now"
    # sample received, so a BY_SOURCE reader rejects it; BY_RECEPTION takes all. "now" sends for 10 s: "late"'s
    # start-up (seconds on a loaded machine) and its 2 s of samples fall inside that.
    now = spawn(mrt("talk", "--topic", topic, "--count", "200", "--rate", "20", "--prefix", "now",
                    "--node-name", "talker_now", "--wait-subscribers", "1", "--linger", "2"))
    now.wait_for(lambda e: e.get("event") == "sent" and e["seq"] == 5, 20)
    late = spawn(mrt("talk", "--topic", topic, "--count", "40", "--rate", "20", "--prefix", "late",
                     "--node-name", "talker_late", "--wait-subscribers", "1", "--linger", "1", "--clock-offset", "-0.3"))
    late.wait_for("done", 30)
    now.wait_for("done", 30)
    listener.wait_for(lambda e: e.get("event") == "recv" and str(e.get("data")).startswith("now 199"), 10)
    got = received(listener)
    n_now = sum(1 for x in got if x.startswith("now"))
    n_late = sum(1 for x in got if x.startswith("late"))
    assert set(transports(listener)) == {"DDS"}
    print(f"order by_source={by_source}: now={n_now}/200 late={n_late}/40")
    assert n_now == 200, n_now
    if by_source:
        assert n_late <= 3, got  # only while "now" is silent could one slip through
    else:
        assert n_late == 40, n_late


def test_lagging_publisher_clock_is_reported(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/qskew", "--duration", "8", "--node-name", "skew_listener"))
    listener.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/qskew", "--count", "40", "--rate", "20", "--wait-subscribers", "1",
              "--node-name", "skewed_talker", "--clock-offset", "-5"))
    ev = listener.wait_for(lambda e: e.get("event") == "log" and "clock" in e.get("text", ""), 20)
    text = ev["text"]
    assert ev["level"] == "WARNING"
    assert "skewed_talker" in text and "behind" in text and "NTP" in text
    lag = float(re.search(r"runs ([0-9.]+) s behind", text).group(1))  # type: ignore[union-attr]
    print(f"skew: {text}")
    assert 4.5 <= lag <= 6.0, text
    time.sleep(1.0)
    assert sum("clock" in t for t in logs(listener)) == 1  # reported once, not per sample


def test_synchronised_publisher_clock_is_not_reported(ros_master: harness.RosMaster,
                                                      spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/qnoskew", "--duration", "30", "--exit-after", "30"))
    listener.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/qnoskew", "--count", "30", "--rate", "20", "--wait-subscribers", "1"))
    listener.wait_for("done", 40)
    assert listener.count("recv") == 30
    assert not [t for t in logs(listener) if "clock" in t]


# ---------------------------------------------------------------------------
# 6. transport_priority on the wire (TCPROS)


def _captured_tos(bpf_filter: str, n: int = 6, timeout: float = 15.0) -> list[int]:
    """The IP TOS byte of the next ``n`` loopback packets matching ``bpf_filter`` (tcpdump)."""
    cap = subprocess.Popen(["tcpdump", "-i", "lo", "-nn", "-v", "-l", "-c", str(n), bpf_filter],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = cap.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        cap.kill()
        out, err = cap.communicate()
    toses = [int(m, 16) for m in re.findall(r"tos (0x[0-9a-f]+)", out)]
    assert len(toses) >= 3, (out, err)
    return toses


@pytest.mark.parametrize("priority,tos", [("HIGH", 0x88), ("EXTREMELY_HIGH", 0xb8), ("NORMAL", 0x0)])
def test_transport_priority_marks_tcpros_packets(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                 priority: str, tos: int) -> None:
    topic = f"/qprio_{priority.lower()}"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", "12", "--hints", "tcp"))
    listener.wait_for("ready", 30)
    talker_name = f"prio_talker_{priority.lower()}"
    talker = spawn(mrt("talk", "--topic", topic, "--count", "400", "--rate", "40", "--wait-subscribers", "1",
                       "--node-name", talker_name, qos={"transport_priority": priority}))
    listener.wait_for_count("recv", 3, timeout=20)
    assert set(transports(listener)) == {"TCPROS"}
    # the talker's TCPROS server port, as ROS 1 hands it out (the source port of its data packets)
    proto = harness.node_call(harness.lookup_node(ros_master, talker_name), "requestTopic", topic, [["TCPROS"]])
    assert proto[0] == "TCPROS", proto
    assert any(local.endswith(f":{proto[2]}") for local, _peer in tcp_links_between(talker.pid, listener.pid))
    toses = _captured_tos(f"tcp src port {proto[2]} and greater 70")  # data packets, not bare ACKs (66 B)
    print(f"tos {priority}: {sorted(set(hex(t) for t in toses))} on {len(toses)} packets")
    assert set(toses) == {tos}, toses


# ---------------------------------------------------------------------------
# data_centric_update: refused through the public API


def test_data_centric_update_is_refused_through_public_api() -> None:
    with pytest.raises(UnsupportedQoSError, match="data_centric_update"):
        micros_rt.AdvertiseQoSOptions(data_centric_update=True)
    with pytest.raises(UnsupportedQoSError, match="key"):
        micros_rt.SubscribeQoSOptions(data_centric_update=True)
    with pytest.raises(UnsupportedQoSError):
        micros_rt.AdvertiseQoSOptions.from_dict({"data_centric_update": True}, source="a test")


# ---------------------------------------------------------------------------
# transport_priority on DDS: micros_rt marks Cyclone's UDP sockets (per process)


def _udp_ports_of(pid: int) -> set[int]:
    out = subprocess.run(["ss", "-unapH"], capture_output=True, text=True, timeout=10).stdout
    ports = set()
    for line in out.splitlines():
        if f"pid={pid}," in line:
            ports.add(int(line.split()[3].rsplit(":", 1)[1]))
    return ports


@pytest.mark.parametrize("priority,tos", [("EXTREMELY_HIGH", 0xb8), ("NORMAL", 0x0)])
def test_transport_priority_marks_dds_packets(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                             priority: str, tos: int) -> None:
    topic = f"/qprio_dds_{priority.lower()}"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", "12"))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", topic, "--count", "400", "--rate", "40", "--wait-subscribers", "1",
                       qos={"transport_priority": priority}))
    listener.wait_for_count("recv", 3, timeout=20)
    assert set(transports(listener)) == {"DDS"}
    ports = _udp_ports_of(talker.pid)  # the talker's only UDP sockets are Cyclone's
    assert ports, "talker has no UDP socket"
    flt = " or ".join(f"src port {p}" for p in sorted(ports))
    toses = _captured_tos(f"udp and ({flt})")
    print(f"DDS tos {priority}: {sorted(set(hex(t) for t in toses))} on {len(toses)} packets")
    assert set(toses) == {tos}, toses
