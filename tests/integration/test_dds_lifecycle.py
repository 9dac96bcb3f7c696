"""DDS entities of a long-running node: topics released with their last reader/writer, and a killed
publisher noticed within the participant lease (issue 9, defects 4 and 6). Real processes, real master."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from typing import Any, Dict

import pytest

import harness
from helpers import mrt

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

TOPICS_SCRIPT = """
import json
import micros_rt
from cyclonedds.core import Entity
from cyclonedds.topic import Topic
from std_msgs.msg import String

def topics():
    return sum(isinstance(e, Topic) for e in list(Entity._entities.values()))

micros_rt.init_node("topic_churn")
nh = micros_rt.NodeHandle()
import time
keep = nh.advertise("kept", String, 10)   # the participant (and ROS 2 graph topic) exist from here on
deadline = time.monotonic() + 10
while topics() < 2 and time.monotonic() < deadline:   # ros_discovery_info starts in the background
    time.sleep(0.05)
base = topics()
for i in range(300):
    nh.advertise("churn_pub_%d" % i, String, 10).unregister()
    nh.subscribe("churn_sub_%d" % i, String, lambda m: None, 10).unregister()
after = topics()
shared_a = nh.advertise("shared", String, 10)
shared_b = nh.subscribe("shared", String, lambda m: None, 10)
with_both = topics()
shared_a.unregister()
one_left = topics()
shared_b.unregister()
print(json.dumps({"base": base, "after": after, "with_both": with_both, "one_left": one_left,
                  "end": topics()}) + "\\n", end="", flush=True)
micros_rt.shutdown()
"""


def test_topics_are_released_with_their_last_reader_or_writer(ros_master: harness.RosMaster) -> None:
    cp = subprocess.run([harness.MICROS_RT_PYTHON, "-c", TOPICS_SCRIPT], env=ros_master.env, capture_output=True,
                        text=True, timeout=180)
    assert cp.returncode == 0, cp.stderr[-3000:]
    r: Dict[str, Any] = json.loads(cp.stdout.strip().splitlines()[-1])
    print(f"\nTopic entities: {r}")
    assert r["after"] == r["base"], f"600 advertise/subscribe + unregister left {r['after'] - r['base']} Topics: {r}"
    assert r["with_both"] == r["base"] + 1, r   # a reader and a writer of one topic share one Topic
    assert r["one_left"] == r["base"] + 1 and r["end"] == r["base"], r


def test_killed_publisher_leaves_the_connections_within_two_seconds(ros_master: harness.RosMaster,
                                                                     spawn: harness.Spawner) -> None:
    listener = spawn(mrt("listen", "--topic", "/lease", "--duration", "60", "--node-name", "lease_listener"))
    listener.wait_for("ready", 30)
    talker = spawn(mrt("talk", "--topic", "/lease", "--count", "100000", "--rate", "50",
                       "--node-name", "lease_talker"))
    listener.wait_for_count("recv", 10, timeout=30)
    uri = harness.lookup_node(ros_master, "/lease_listener")

    def dds_links() -> int:
        info = harness.node_call(uri, "getBusInfo")
        return sum(1 for c in info if c[4] == "/lease" and c[3] == "DDS")

    assert dds_links() == 1
    os.kill(talker.pid, signal.SIGKILL)
    killed = time.monotonic()
    harness.wait_until(lambda: dds_links() == 0, 10, interval=0.02, message="the killed publisher's DDS link gone")
    noticed = time.monotonic() - killed
    print(f"\nSIGKILLed DDS publisher left the subscriber's connections after {noticed:.2f} s")
    # the lease (1.5 s) and the subscriber's check; a loaded machine adds to both. Without liveliness it was never
    assert noticed < 3.5, f"noticed after {noticed:.2f} s (lease 1.5 s)"
