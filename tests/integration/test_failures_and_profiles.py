"""DDS that cannot start, and YAML profiles applied without code changes."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

import harness
from helpers import logs, mrt, received, stock_talker, transports

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

BROKEN_CYCLONE = (
    '<CycloneDDS><Domain id="any"><General><Interfaces>'
    '<NetworkInterface name="no_such_interface0"/></Interfaces></General></Domain></CycloneDDS>'
)


def test_dds_that_cannot_start_means_tcpros_with_one_warning(ros_master: harness.RosMaster,
                                                            spawn: harness.Spawner, tmp_path: Path) -> None:
    cfg = tmp_path / "broken_cyclone.xml"
    cfg.write_text(BROKEN_CYCLONE)
    broken = dict(ros_master.env, CYCLONEDDS_URI=cfg.as_uri())
    listener = spawn(mrt("listen", "--topic", "/no_dds", "--duration", "20"), env=broken)
    listener.wait_for("ready", 30)
    spawn(mrt("talk", "--topic", "/no_dds", "--count", "200", "--rate", "30", "--wait-subscribers", "1"))
    listener.wait_for_count("recv", 10, timeout=30)
    assert set(transports(listener)) == {"TCPROS"}
    warnings = [w for w in logs(listener) if "DDS is unavailable" in w]
    assert len(warnings) == 1, logs(listener)
    assert "TCPROS" in warnings[0]


def test_yaml_profile_gives_time_filter_without_code_changes(ros_master: harness.RosMaster,
                                                             spawn: harness.Spawner, tmp_path: Path) -> None:
    profile = tmp_path / "qos.yaml"
    profile.write_text("subscribers:\n  /profiled: {time_filter_duration: 1.0}\n")
    env = dict(ros_master.env, MICROS_RT_QOS_PROFILE=str(profile))
    # plain subscribe() in the peer: the filter can only come from the file
    # the listeners run until stopped: the talker's start-up on a loaded machine does not eat their window
    listener = spawn(mrt("listen", "--topic", "/profiled", "--duration", "60"), env=env)
    unfiltered = spawn(mrt("listen", "--topic", "/profiled", "--duration", "60", "--node-name", "unfiltered"))
    listener.wait_for("ready", 30)
    unfiltered.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/profiled", "--count", "200", "--rate", "50", "--wait-subscribers", "2"))
    talker.wait(30)
    time.sleep(1.0)  # a bounded look for the last messages in flight
    listener.stop()
    unfiltered.stop()
    n_filtered, n_all = len(received(listener)), len(received(unfiltered))
    assert n_all >= 150, n_all
    assert 2 <= n_filtered <= 6, n_filtered  # 4 s of data at 1 message per second


def test_bad_yaml_profile_is_a_clear_error(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                           tmp_path: Path) -> None:
    profile = tmp_path / "bad.yaml"
    profile.write_text("subscribers:\n  /x: {time_filter: 1.0}\n")
    env = dict(ros_master.env, MICROS_RT_QOS_PROFILE=str(profile))
    peer = spawn(mrt("listen", "--topic", "/x", "--duration", "3"), env=env)
    rc = peer.wait(30)
    assert rc != 0
    tail = peer.stderr_tail()
    assert "bad.yaml:2" in tail and "time_filter" in tail, tail


def test_master_restart_keeps_data_flowing_and_reregisters(fresh_master: harness.RosMaster,
                                                           spawn: harness.Spawner) -> None:
    env = fresh_master.env
    listener = spawn(mrt("listen", "--topic", "/survivor", "--duration", "60", "--node-name", "survivor_l"), env=env)
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/survivor", "--count", "2000", "--rate", "20",
                       "--node-name", "survivor_t"), env=env)
    listener.wait_for_count("recv", 10, timeout=30)
    fresh_master.stop()
    # no master at all: DDS still carries the data
    before = listener.count("recv")
    listener.wait_for_count("recv", before + 20, timeout=15)
    talker.wait_for(lambda e: e.get("event") == "log" and "does not answer" in e.get("text", ""), 15)
    fresh_master.start()
    listener.wait_for(lambda e: e.get("event") == "log" and "re-registered" in e.get("text", ""), 20)
    harness.wait_until(lambda: {"/survivor_l", "/survivor_t"} <= set(
        harness.rosnode(fresh_master, "list", check=False).stdout.split()), 20, interval=0.5,
        message="nodes re-registered with the restarted master")
    # a publisher that appears after the restart is found through the re-registered subscription
    spawn(stock_talker("--topic", "/survivor", "--count", "200", "--rate", "20", "--prefix", "late_stock"), env=env)
    listener.wait_for(lambda e: e.get("event") == "recv" and str(e.get("data", "")).startswith("late_stock"), 30)


def test_malformed_request_topic_is_answered_and_the_node_keeps_serving(ros_master: harness.RosMaster,
                                                                        spawn: harness.Spawner) -> None:
    talker = spawn(mrt("talk", "--topic", "/robust", "--count", "1000", "--rate", "20", "--node-name", "robust"))
    talker.wait_for("ready", 30)
    uri = harness.lookup_node(ros_master, "/robust")
    # DDS parameters that are not a dict: DDS is declined in words, TCPROS is chosen
    code, msg, proto = harness.node_call_raw(uri, "requestTopic", "/robust", [["DDS", "garbage"], ["TCPROS"]])
    assert code == 1 and proto[0] == "TCPROS", (code, msg, proto)
    # DDS parameters with wrong values and nothing else offered: a refusal, not a crash
    code, msg, proto = harness.node_call_raw(uri, "requestTopic", "/robust",
                                             [["DDS", {"domain": "x", "qos": {"bogus": 1}}]])
    assert code == 0 and proto == [], (code, msg, proto)
    # not even a protocol list
    code, msg, _ = harness.node_call_raw(uri, "requestTopic", "/robust", "not a list")
    assert code != 1
    code, msg, _ = harness.node_call_raw(uri, "requestTopic", "/robust", [[]])
    assert code != 1
    # micros_rt logs from a logging thread of its own (never blocking its callers): wait for the lines
    harness.wait_until(lambda: [w for w in logs(talker) if "DDS" in w], 10, message=f"DDS decline lines in the "
                       f"talker's log; it has: {logs(talker)}")
    # and it still serves a stock subscriber
    cp = harness.rostopic(ros_master, "echo", "-n", "1", "/robust", timeout=30)
    assert "hello" in cp.stdout, cp.stdout


RELEASE_SCRIPT = """
import json, sys, threading, time
import micros_rt
from cyclonedds.core import Entity, GuardCondition, WaitSet
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from std_msgs.msg import String

def topic_name(e):
    try:
        return e.topic.get_name()
    except AttributeError:  # registered, not yet built: the ROS 2 graph announcer's writer, made on its own thread
        return ""

def state():
    live = list(Entity._entities.values())  # cyclonedds' registry of entities not yet deleted
    # data endpoints only (rt/...): the node's ros_discovery_info announcement lives with the node
    data = [e for e in live if isinstance(e, (DataWriter, DataReader)) and topic_name(e).startswith("rt/")]
    return {"writers": sum(isinstance(e, DataWriter) for e in data),
            "readers": sum(isinstance(e, DataReader) for e in data),
            "waitsets": sum(isinstance(e, (WaitSet, GuardCondition)) for e in live),
            "delivery_threads": sum(t.name.startswith("micros_rt delivery") for t in threading.enumerate())}

micros_rt.init_node("releaser")
nh = micros_rt.NodeHandle()
base = state()
pub = nh.advertise("released", String, 10, latch=True)
sub = nh.subscribe("released", String, lambda m: None, 10)
during = state()
pub.unregister()
sub.unregister()
sub.unregister()  # twice is harmless
after = state()
sys.stdout.write(json.dumps({"base": base, "during": during, "after": after}) + "\\n")  # one write
sys.stdout.flush()
micros_rt.shutdown()
"""


def test_unregister_releases_writers_readers_and_threads(ros_master: harness.RosMaster) -> None:
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", RELEASE_SCRIPT], env=ros_master.env,
                        capture_output=True, text=True, timeout=60)
    assert cp.returncode == 0, cp.stderr
    report = json.loads(cp.stdout.strip().splitlines()[-1])
    assert report["base"] == {"writers": 0, "readers": 0, "waitsets": 0, "delivery_threads": 0}, report
    assert report["during"] == {"writers": 1, "readers": 1, "waitsets": 2, "delivery_threads": 1}, report
    assert report["after"] == report["base"], report


BAD_WRITER_SCRIPT = """
import os, struct, sys, time
from cyclonedds._clayer import ddspy_write
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from std_msgs.msg import String
from micros_rt.transports.dds.types import dds_type_for

# a foreign (untagged) DDS writer on the micros_rt topic: first broken samples, then good ones
t = dds_type_for(String)
dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
writer = DataWriter(dp, Topic(dp, "rt/poisoned", t.idl_class))
deadline = time.monotonic() + 30  # discovery: the listener makes its DDS reader once it sees this participant
while not writer.get_matched_subscriptions() and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.2)
for i in range(5):
    bad = b"\\x00\\x01\\x00\\x00" + struct.pack("<I", 3) + b"\\xff\\xfe\\x00"  # not UTF-8
    ddspy_write(writer._ref, bad + bytes(-len(bad) % 4))
    time.sleep(0.05)
for i in range(5):
    writer.write(t.idl_class(data=f"good {i}"))
    time.sleep(0.05)
time.sleep(1.0)
print("sent", flush=True)
"""


def test_malformed_dds_samples_are_reported_once_and_good_ones_still_arrive(ros_master: harness.RosMaster,
                                                                            spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/poisoned", "--duration", "20"))
    listener.wait_for("ready", 30)
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", BAD_WRITER_SCRIPT], env=ros_master.env,
                        capture_output=True, text=True, timeout=60)
    assert cp.returncode == 0 and "sent" in cp.stdout, cp.stderr
    listener.wait_for_count("recv", 5, timeout=10)
    assert received(listener) == [f"good {i}" for i in range(5)]
    warnings = [w for w in logs(listener) if "malformed DDS sample" in w]
    assert len(warnings) == 1, logs(listener)  # once per writer, not once per sample
    assert "std_msgs/String" in warnings[0]
    assert listener.alive()


def test_a_publishers_profile_keeps_its_topic_off_dds_without_a_warning(ros_master: harness.RosMaster,
                                                                       spawn: harness.Spawner,
                                                                       tmp_path: Path) -> None:
    # The sending robot's own file: /tcp_only is served over TCPROS only (no DDS writer), so a micros_rt
    # subscriber that offers DDS first still gets TCPROS, and the tools say why; a topic the file does not name
    # stays on DDS.
    profile = tmp_path / "robot.yaml"
    profile.write_text("publishers:\n  /tcp_only: {transport_hints: [TCPROS], transport_priority: LOW}\n")
    env = dict(ros_master.env, MICROS_RT_QOS_PROFILE=str(profile))
    off = spawn(mrt("listen", "--topic", "/tcp_only", "--duration", "40", "--node-name", "off_l"))
    on = spawn(mrt("listen", "--topic", "/dds_still", "--duration", "40", "--node-name", "on_l"))
    off.wait_for("ready", 30)
    on.wait_for("ready", 30)
    talkers = [spawn(mrt("talk", "--topic", topic, "--count", "1200", "--rate", "30", "--wait-subscribers", "1",
                         "--node-name", name), env=env)
               for topic, name in (("/tcp_only", "off_t"), ("/dds_still", "on_t"))]
    off.wait_for_count("recv", 10, timeout=30)
    on.wait_for_count("recv", 10, timeout=30)
    assert set(transports(off)) == {"TCPROS"} and set(transports(on)) == {"DDS"}
    cp = subprocess.run([str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt"), "topic", "info", "--json",
                         "/tcp_only"], env=dict(ros_master.env), capture_output=True, text=True, timeout=90)
    assert cp.returncode == 0, cp.stderr
    (link,) = [x for x in json.loads(cp.stdout)["links"] if x["subscriber"] == "/off_l"]
    assert link["protocol"] == "TCPROS" and link["verdict"] == "profile", link
    assert "robot.yaml" in link["reason"] and "keeps it off DDS" in link["reason"], link
    for peer in (off, *talkers):
        assert not [w for w in logs(peer) if "DDS" in w], logs(peer)
