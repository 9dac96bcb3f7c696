"""The DDS data plane between micros_rt nodes, negotiated per publisher inside the ROS 1 graph."""

from __future__ import annotations

import collections
import time

import pytest

import harness
from helpers import bus_info, data_links_between, mrt, received, stock_talker, transports

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)


def test_micros_rt_pair_uses_dds_not_tcp(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/dds_pair", "--duration", "30", "--node-name", "dds_listener"))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/dds_pair", "--count", "300", "--rate", "20",
                       "--node-name", "dds_talker", "--wait-subscribers", "1"))
    listener.wait_for_count("recv", 20, timeout=30)
    assert set(transports(listener)) == {"DDS"}
    # from outside our bookkeeping: the kernel shows no TCP link between the two processes
    assert data_links_between(ros_master, ("/dds_listener", listener.pid), ("/dds_talker", talker.pid)) == []
    # and stock rosnode sees a DDS transport on both sides
    sub_conns = [c for c in bus_info(ros_master, "/dds_listener") if c[4] == "/dds_pair"]
    pub_conns = [c for c in bus_info(ros_master, "/dds_talker") if c[4] == "/dds_pair"]
    assert [c[3] for c in sub_conns] == ["DDS"] and [c[3] for c in pub_conns] == ["DDS"]
    out = harness.rosnode(ros_master, "info", "/dds_talker", timeout=20).stdout
    assert "DDS" in out, out
    got = received(listener)
    nums = [int(x.split()[1]) for x in got]
    assert nums == sorted(nums) and len(set(nums)) == len(nums)


@pytest.mark.parametrize("hints,expected", [
    ("tcp", "TCPROS"),
    ("dds", "DDS"),
    ("dds,tcp", "DDS"),
    ("tcp,dds", "TCPROS"),
    (None, "DDS"),
])
def test_transport_hints_choose_protocol(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                         hints: str | None, expected: str) -> None:
    topic = f"/hints_{(hints or 'default').replace(',', '_')}"
    args = ["--topic", topic, "--duration", "25"]
    if hints:
        args += ["--hints", hints]
    listener = spawn(mrt("listen", *args))
    listener.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", topic, "--count", "300", "--rate", "30", "--wait-subscribers", "1"))
    listener.wait_for_count("recv", 10, timeout=30)
    assert set(transports(listener)) == {expected}


def test_dds_only_hints_with_stock_publisher_warns(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/dds_only", "--duration", "20", "--hints", "dds"))
    listener.wait_for("ready", 30)
    spawn(stock_talker("--topic", "/dds_only", "--count", "100", "--rate", "20"))
    listener.wait_for(lambda e: e.get("event") == "log" and "DDS" in e.get("text", "")
                      and "stock" in e.get("text", "").lower(), timeout=20)
    assert listener.count("recv") == 0


def test_mixed_publishers_exactly_once(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/mixed", "--duration", "40", "--queue-size", "1000"))
    listener.wait_for("ready", 30)
    n = 100
    t1 = spawn(mrt("talk", "--topic", "/mixed", "--count", n, "--rate", "50", "--prefix", "mrt",
                   "--wait-subscribers", "1", "--linger", "3"))
    t2 = spawn(stock_talker("--topic", "/mixed", "--count", n, "--rate", "50", "--prefix", "stock",
                            "--wait-subscribers", "1", "--linger", "3"))
    expected = {f"mrt {i}" for i in range(n)} | {f"stock {i}" for i in range(n)}
    try:
        listener.wait_for_count("recv", 2 * n, timeout=40)
    except AssertionError as exc:  # say which messages are missing, and how each talker saw its subscriber
        missing = sorted(expected - set(received(listener)), key=lambda d: (d.split()[0], int(d.split()[1])))
        raise AssertionError(f"{exc}\nmissing: {missing[:20]}\nmrt talker: {t1.events('connections')[:5]}\n"
                             f"stock talker: {t2.events('connections')[:5]}") from None
    t1.wait(30)
    t2.wait(30)
    got = received(listener)
    counts = collections.Counter(got)
    assert all(c == 1 for c in counts.values()), [k for k, c in counts.items() if c > 1][:5]
    assert set(got) == expected
    by_prefix = {(e["data"].split()[0], e["transport"]) for e in listener.events("recv")}
    assert by_prefix == {("mrt", "DDS"), ("stock", "TCPROS")}


def test_one_publisher_serves_dds_and_tcpros(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    dds_l = spawn(mrt("listen", "--topic", "/both", "--duration", "30"))
    tcp_l = spawn(mrt("listen", "--topic", "/both", "--duration", "30", "--hints", "tcp", "--node-name", "tcp_l"))
    dds_l.wait_for("ready", 30)
    tcp_l.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/both", "--count", "60", "--rate", "30", "--wait-subscribers", "2"))
    dds_l.wait_for_count("recv", 40, timeout=30)
    tcp_l.wait_for_count("recv", 40, timeout=30)
    assert set(transports(dds_l)) == {"DDS"}
    assert set(transports(tcp_l)) == {"TCPROS"}


def test_latched_message_reaches_late_subscriber_over_dds(ros_master: harness.RosMaster,
                                                          spawn: harness.Spawner) -> None:
    talker = spawn(mrt("talk", "--topic", "/latched", "--count", "3", "--rate", "20", "--latch",
                       "--linger", "30", "--prefix", "latched"))
    talker.wait_for("done", 30) if False else talker.wait_for(lambda e: e.get("seq") == 2, 30)
    time.sleep(0.5)  # the subscriber must join after the last publish: that is the point of the test
    listener = spawn(mrt("listen", "--topic", "/latched", "--duration", "15"))
    ev = listener.wait_for("recv", 20)
    assert ev["data"] == "latched 2"
    assert ev["transport"] == "DDS"
    time.sleep(1.0)
    assert received(listener) == ["latched 2"]


def test_two_masters_on_one_domain_stay_apart(ros_master: harness.RosMaster, fresh_master: harness.RosMaster,
                                              spawn: harness.Spawner) -> None:
    a = spawn(mrt("listen", "--topic", "/shared", "--duration", "20"))
    b = spawn(mrt("listen", "--topic", "/shared", "--duration", "20"), env=fresh_master.env)
    a.wait_for("ready", 30)
    b.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/shared", "--count", "100", "--rate", "30", "--prefix", "graphA",
              "--wait-subscribers", "1"))
    spawn(mrt("talk", "--topic", "/shared", "--count", "100", "--rate", "30", "--prefix", "graphB",
              "--wait-subscribers", "1"), env=fresh_master.env)
    a.wait_for_count("recv", 30, timeout=30)
    b.wait_for_count("recv", 30, timeout=30)
    assert {x.split()[0] for x in received(a)} == {"graphA"}
    assert {x.split()[0] for x in received(b)} == {"graphB"}


def test_incompatible_qos_falls_back_to_tcpros_with_warning(ros_master: harness.RosMaster,
                                                           spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/be_clash", "--duration", "25",
                         qos={"using_best_effort_protocol": False}))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/be_clash", "--count", "300", "--rate", "30", "--wait-subscribers", "1",
                       qos={"using_best_effort_protocol": True}))
    listener.wait_for_count("recv", 10, timeout=30)
    assert set(transports(listener)) == {"TCPROS"}
    warning = talker.wait_for(lambda e: e.get("event") == "log" and "using_best_effort_protocol" in e["text"], 10)
    assert "True" in warning["text"] and "False" in warning["text"]


def test_md5_mismatch_is_refused(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/typed", "--type", "std_msgs/Int32", "--duration", "12"))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/typed", "--count", "200", "--rate", "20"))
    talker.wait_for(lambda e: e.get("event") == "log" and "md5" in e["text"], 20)
    time.sleep(1.0)
    assert listener.count("recv") == 0


def test_publisher_killed_and_restarted_is_heard_again(ros_master: harness.RosMaster,
                                                      spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/phoenix", "--duration", "60"))
    listener.wait_for("ready", 30)
    first = spawn(mrt("talk", "--topic", "/phoenix", "--count", "1000", "--rate", "20", "--prefix", "first",
                      "--node-name", "phoenix"))
    listener.wait_for_count("recv", 5, timeout=30)
    first.proc.kill()
    first.wait(10)
    # DDS tells the subscriber its publisher is gone (participant lease): bus info stays true
    n = len(listener.events())
    listener.wait_for(lambda e: e.get("event") == "status" and e.get("transports") == {}, 20, start=n)
    spawn(mrt("talk", "--topic", "/phoenix", "--count", "1000", "--rate", "20", "--prefix", "second",
              "--node-name", "phoenix"))
    listener.wait_for(lambda e: e.get("event") == "recv" and str(e.get("data", "")).startswith("second"), 30)
    assert listener.alive()
    assert transports(listener)[-1] == "DDS"
