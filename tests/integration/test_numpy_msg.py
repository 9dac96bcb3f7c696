"""rospy.numpy_msg classes across processes: numeric arrays arrive as numpy arrays over DDS (micros_rt) and
TCPROS (stock rospy), and as ROS 1's tuples for a plain subscriber of the same topic."""

from __future__ import annotations

import json

import pytest

import harness
from helpers import mrt, stock_listener

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

# float32-exact values (k/4), so the three subscribers' figures compare exactly
RANGES = [k * 0.25 for k in range(-40, 1041)]
INTENSITIES = [float(k % 7) for k in range(1081)]


def test_numpy_laser_scan_reaches_numpy_plain_and_stock_subscribers(ros_master: harness.RosMaster,
                                                                     spawn: harness.Spawner) -> None:
    scan = ["--topic", "/np_scan", "--type", "sensor_msgs/LaserScan"]
    np_dds = spawn(mrt("listen", *scan, "--numpy", "--full-msg", "--duration", 40, "--node-name", "np_dds"))
    plain_dds = spawn(mrt("listen", *scan, "--full-msg", "--duration", 40, "--node-name", "plain_dds"))
    np_stock = spawn(stock_listener(*scan, "--numpy", "--count", 5, "--duration", 40))
    for peer in (np_dds, plain_dds, np_stock):
        peer.wait_for("ready", 30)
    data = {"header": {"frame_id": "scan {i}"}, "angle_min": -2.25, "ranges": RANGES, "intensities": INTENSITIES}
    spawn(mrt("talk", *scan, "--numpy", "--data-json", json.dumps(data), "--count", 5, "--rate", 10,
              "--wait-subscribers", 3, "--linger", 2))

    for peer in (np_dds, plain_dds):
        events = peer.wait_for_count("recv", 5, timeout=30)
        assert {e["transport"] for e in events} == {"DDS"}
        assert [e["msg"]["header"]["frame_id"] for e in events] == [f"scan {i}" for i in range(5)]
    # numpy_msg subscriber: float32 numpy arrays holding the values sent
    got = np_dds.events("recv")[0]["msg"]
    assert got["ranges"] == {"ndarray": "<f4", "values": RANGES}
    assert got["intensities"] == {"ndarray": "<f4", "values": INTENSITIES}
    assert got["angle_min"] == -2.25
    # plain subscriber of the same topic: ROS 1's sequences of floats, not arrays
    plain = plain_dds.events("recv")[0]["msg"]
    assert plain["ranges"] == RANGES and plain["intensities"] == INTENSITIES
    # stock rospy's numpy_msg subscriber reads the micros_rt publisher's TCPROS side
    events = np_stock.wait_for_count("recv", 5, timeout=30)
    assert events[0]["msg"]["ranges"] == {"ndarray": "<f4", "values": RANGES}
    assert events[0]["msg"]["header"]["frame_id"] == "scan 0"
