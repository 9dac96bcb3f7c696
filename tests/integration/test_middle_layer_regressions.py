"""Regression tests for defects a hostile tester found in the middle layer (issue 9): each runs a real
micros_rt node (a subprocess of the project venv) against the session's real rosmaster."""

from __future__ import annotations

import json
import subprocess
from typing import Any, Dict

import pytest

import harness
from helpers import mrt

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

STATE = """
import json, threading, time, sys
import micros_rt
from micros_rt.core.runtime import _node
from cyclonedds.core import Entity, GuardCondition, WaitSet
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader

def state():
    live = list(Entity._entities.values())
    data = [e for e in live if isinstance(e, (DataWriter, DataReader)) and e.topic.get_name().startswith("rt/")]
    return {"writers": sum(isinstance(e, DataWriter) for e in data),
            "readers": sum(isinstance(e, DataReader) for e in data),
            "waitsets": sum(isinstance(e, (WaitSet, GuardCondition)) for e in live),
            "threads": sum(t.name.startswith("micros_rt delivery") for t in threading.enumerate()),
            "publications": len(_node.publications), "subscriptions": len(_node.subscriptions)}
"""


def run_script(master: harness.RosMaster, body: str, timeout: float = 90.0) -> Dict[str, Any]:
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", STATE + body], env=master.env, capture_output=True,
                        text=True, timeout=timeout)
    assert cp.returncode == 0, cp.stderr[-3000:]
    report: Dict[str, Any] = json.loads(cp.stdout.strip().splitlines()[-1])
    return report


def test_failed_registration_leaks_nothing(ros_master: harness.RosMaster) -> None:
    # rospy refusing the registration (here: made to raise) must not leave a reader, a wait set, a
    # delivery thread or a findable endpoint behind (they were created before rospy was asked)
    report = run_script(ros_master, """
import rospy
import micros_rt.transports.tcpros.patches as compat
from std_msgs.msg import String
micros_rt.init_node("leaky")
nh = micros_rt.NodeHandle()
base = state()
# the rospy classes the compat module registers with (captured at import: `micros-rt run` replaces
# rospy's public names with drop-in classes)
real_sub, real_pub = compat.ROSPY_SUBSCRIBER, compat.ROSPY_PUBLISHER
def refuse(*a, **k):
    raise rospy.ROSException("registration refused (test)")
errors = []
compat.ROSPY_SUBSCRIBER = compat.ROSPY_PUBLISHER = refuse
for i in range(20):
    for make in (lambda: nh.subscribe("leak%d" % i, String, lambda m: None, 10),
                 lambda: nh.advertise("leak%d" % i, String, 10)):
        try:
            make()
        except rospy.ROSException as exc:
            errors.append(str(exc))
compat.ROSPY_SUBSCRIBER, compat.ROSPY_PUBLISHER = real_sub, real_pub
after = state()
# and the same topics work afterwards
sub = nh.subscribe("leak0", String, lambda m: None, 10)
pub = nh.advertise("leak0", String, 10)
working = state()
sys.stdout.write(json.dumps({"base": base, "after": after, "errors": len(errors), "working": working}) + "\\n")
sys.stdout.flush()
micros_rt.shutdown()
""")
    assert report["errors"] == 40, report
    assert report["after"] == report["base"], report
    assert report["working"]["publications"] == 1 and report["working"]["subscriptions"] == 1, report


def test_concurrent_advertise_and_unregister_never_hand_out_a_closing_publication(
        ros_master: harness.RosMaster) -> None:
    report = run_script(ros_master, """
from std_msgs.msg import String
micros_rt.init_node("racer")
nh = micros_rt.NodeHandle()
base = state()
failures = []
def worker(k):
    for i in range(60):
        try:
            pub = nh.advertise("race", String, 10)
            pub.publish(String(data="x"))   # a closed publication would raise here
            pub.unregister()
        except Exception as exc:
            failures.append(repr(exc))
threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
for t in threads: t.start()
for t in threads: t.join()
print(json.dumps({"base": base, "after": state(), "failures": failures[:5], "n_failures": len(failures)}) + "\\n", end="",
      flush=True)
micros_rt.shutdown()
""", timeout=150)
    assert report["n_failures"] == 0, report
    assert report["after"] == report["base"], report


def test_two_latched_publishers_connecting_at_once_make_one_latched_reader(ros_master: harness.RosMaster) -> None:
    report = run_script(ros_master, """
import uuid
from std_msgs.msg import String
from micros_rt.transports.dds.offer import DDSAnswer
from micros_rt.qos import AdvertiseQoSOptions
micros_rt.init_node("latch_race")
nh = micros_rt.NodeHandle()
sub = nh.subscribe("latched_race", String, lambda m: None, 10)
impl = sub._sub
def guid():
    return str(uuid.uuid4())
go = threading.Event()
def connect(k):
    go.wait()
    impl.sides["DDS"].connect("http://127.0.0.1:%d/" % (40000 + k),
                     DDSAnswer(writer=guid(), participant=guid(), latch=True, qos=AdvertiseQoSOptions()))
threads = [threading.Thread(target=connect, args=(k,)) for k in range(8)]
for t in threads: t.start()
go.set()
for t in threads: t.join()
during = state()
sub.unregister()
print(json.dumps({"during": during, "after": state(), "readers_attr": len(impl.sides["DDS"].readers)}) + "\\n", end="", flush=True)
micros_rt.shutdown()
""")
    assert report["during"]["readers"] == 2, report  # the volatile reader and ONE transient-local reader
    assert report["after"]["readers"] == 0 and report["after"]["waitsets"] == 0, report


def test_bad_field_values_raise_before_anything_is_sent(ros_master: harness.RosMaster,
                                                        spawn: harness.Spawner) -> None:
    # Only a DDS subscriber listens: a bad value must raise as stock rospy raises, and reach nobody
    # (String(data=123) used to arrive as 123 NUL bytes; Int32(2**40) was dropped without an error).
    listener = spawn(mrt("listen", "--topic", "/badvalues", "--duration", "40", "--node-name", "bad_listener"))
    others_listening = [spawn(mrt("listen", "--topic", topic, "--type", type_, "--duration", "40",
                                  "--node-name", f"listener{topic.replace('/', '_')}"))
                        for topic, type_ in (("/bad_int", "std_msgs/Int32"), ("/bad_float", "std_msgs/Float64"),
                                             ("/bad_header", "std_msgs/Header"))]
    for peer in [listener, *others_listening]:
        peer.wait_for("ready", 30)
    report = run_script(ros_master, """
import rospy, genpy
from std_msgs.msg import String, Int32, Float64, Header
micros_rt.init_node("bad_talker")
nh = micros_rt.NodeHandle()
pub = nh.advertise("badvalues", String, 10)
deadline = time.monotonic() + 30
while pub.get_num_connections() < 1 and time.monotonic() < deadline:
    time.sleep(0.05)
reaches = [pub.reaches("/bad_listener"), pub.reaches("/listener_bad_int")]  # a subscriber of another topic: no
raised = []
def with_data(value):
    m = String()
    m.data = value  # set after construction (the constructor turns None into "")
    return m
for bad in (with_data(123), with_data(None), with_data([1, 2])):
    try:
        pub.publish(bad)
        raised.append(False)
    except rospy.ROSSerializationException:
        raised.append(True)
others = []
def connected(p):
    deadline = time.monotonic() + 30
    while p.get_num_connections() < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    return p
for cls, value, topic in ((Int32, 2 ** 40, "bad_int"), (Float64, "x", "bad_float")):
    p = connected(nh.advertise(topic, cls, 10))
    try:
        p.publish(cls(data=value))
        others.append(False)
    except rospy.ROSSerializationException:
        others.append(True)
hp = connected(nh.advertise("bad_header", Header, 10))
try:
    hp.publish(Header(stamp=genpy.Time(2 ** 33, 0)))
    others.append(False)
except rospy.ROSSerializationException:
    others.append(True)
time.sleep(1.0)
pub.publish(String(data="good"))
time.sleep(2.0)
print(json.dumps({"raised": raised, "others": others, "reaches": reaches}) + "\\n", end="", flush=True)
micros_rt.shutdown()
""")
    assert report["raised"] == [True, True, True], report
    assert report["reaches"] == [True, False], report
    assert report["others"] == [True, True, True], report
    listener.wait_for(lambda e: e.get("event") == "recv", 15)
    got = [e.get("data") for e in listener.events("recv")]
    assert got == ["good"], got
    for peer in others_listening:
        assert peer.events("recv") == [], peer.events("recv")
