"""A whole robot under the defaults (tests/robot.py): a dozen processes of one host, most of them unmodified rospy
scripts under ``micros-rt run``, micros_rt API nodes with QoS, stock rospy, roscpp and ``rosbag record``; an rclpy
node joins mid-stream, echoes a topic and the latched map, calls the service, sends a goal and leaves. Nothing is
lost, every call and goal is answered, each link is the one expected. Run with ``CYCLONEDDS_URI`` set (the
loopback configuration, as a ROS 2 user has one) and unset (micros_rt's own loopback rule), the two environments
users have; each on a DDS domain of its own, so no ROS 2 peer of another test is seen."""

from __future__ import annotations

import os

import pytest

from robot import COUNT, ORDER, run_robot

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("cyclonedds_uri", [True, False], ids=["CYCLONEDDS_URI", "no_CYCLONEDDS_URI"])
def test_a_whole_robot_under_the_defaults_loses_nothing_and_answers_everything(cyclonedds_uri: bool) -> None:
    domain = 221 + (os.getpid() + int(cyclonedds_uri)) % 10   # the run's own domain is 1..200; AUTO_DOMAIN 201..220
    report = run_robot(domain, cyclonedds_uri=cyclonedds_uri)
    rows = {r["link"]: r for r in report["rows"]}
    expected = {   # link -> (transport, first message that subscriber must get; None: it joins later)
        "run_talker -> run_listener (micros-rt run)": ("SHM", 0),
        "run_talker -> stock rospy listener": ("TCPROS", 0),
        "run_talker -> rosbag record (roscpp)": ("TCPROS", 0),
        "run_talker -> roscpp relay -> run_cpp_listener": ("TCPROS", None),   # the relay advertises on its 1st message
        "run_talker -> rclpy echo (joined mid-stream)": ("DDS", None),
        "mrt_cmd_talker (HIGH) -> mrt_cmd_listener": ("SHM", 0),
        "run_map (latched) -> late run listener": ("SHM", 0),
        "run_map (latched) -> rclpy (transient_local)": ("DDS", 0),
    }
    assert set(rows) == set(expected), sorted(rows)
    for link, (transport, first) in expected.items():
        row = rows[link]
        assert row["received"] > 0 and row["lost"] == 0 and row["duplicates"] == 0 and row["in_order"], row
        assert row["transports"] == [transport], row
        if first is not None:
            assert row["first"] == first, row
    assert rows["run_talker -> run_listener (micros-rt run)"]["received"] == COUNT
    assert rows["run_talker -> rclpy echo (joined mid-stream)"]["received"] == 20
    for name, call in report["calls"].items():
        assert call["answered"] == call["sent"] == call["right"], (name, call)
    goals = report["goals"]
    goal, cancel, ros2_goal = goals.values()
    assert (goal.get("status_name"), goal.get("feedback"), goal.get("feedback_in_order"), goal.get("sequence_ok")) == \
        ("SUCCEEDED", ORDER, True, True), goal
    assert cancel.get("status_name") == "PREEMPTED" and cancel.get("feedback", 0) >= 5, cancel
    assert (ros2_goal.get("status_name"), ros2_goal.get("feedback"), ros2_goal.get("sequence_ok")) == \
        ("SUCCEEDED", 10, True), ros2_goal
