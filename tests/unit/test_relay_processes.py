"""A relay process per transport priority (micros_rt.bridges.relay.processes): which processes, their names and
command lines, and the counters of all of them in one stats event."""

from __future__ import annotations

import sys
from typing import List

from micros_rt.bridges.relay.config import parse_config
from micros_rt.bridges.relay.processes import Children, child_argv, export_priorities, family, process_name
from micros_rt.qos import TransportPriority

CONFIG = """\
graph: robot_a
export:
  /control: {transport_priority: HIGH}
  /image: {transport_priority: LOW, max_rate: 5}
  /camera/*: {transport_priority: LOW}
  /odom: {}
import:
  /robot_b/odom: {}
"""


def test_one_process_per_priority_of_the_exports_highest_first() -> None:
    config = parse_config(CONFIG, source="relay.yaml")
    assert export_priorities(config) == [TransportPriority.HIGH, TransportPriority.NORMAL, TransportPriority.LOW]
    assert export_priorities(parse_config("graph: g\nimport:\n  /robot_b/x: {}\n", source="r.yaml")) == []
    assert process_name("/relay_robot_a", TransportPriority.HIGH) == "/relay_robot_a_high"
    assert family("/relay_robot_a", config) == {"/relay_robot_a", "/relay_robot_a_high", "/relay_robot_a_normal",
                                                "/relay_robot_a_low"}


def test_a_child_runs_one_priority_of_the_same_file_and_keeps_the_remappings_but_the_name() -> None:
    argv = child_argv("relay.yaml", "relay_robot_a_low", "/relay_robot_a", TransportPriority.LOW, poll_period=0.5,
                      json_events=True, stats_period=2.0, ros_args=["__name:=relay_robot_a", "__ns:=/r", "a:=b"])
    assert argv[:3] == [sys.executable, "-m", "micros_rt.bridges.relay"]
    assert argv[argv.index("--exports-of") + 1] == "LOW" and argv[argv.index("--family-of") + 1] == "/relay_robot_a"
    assert argv[argv.index("--name") + 1] == "relay_robot_a_low" and "--json" in argv
    assert argv[-2:] == ["__ns:=/r", "a:=b"]


def test_the_stats_event_carries_every_process_exports() -> None:
    lines: List[str] = []
    children = Children([TransportPriority.HIGH], lambda p: [], lambda p: "/relay_a_high", lines.append)
    children._forward("/relay_a_high", '{"event": "stats", "exports": [{"topic": "/control", "sent": 3}], '
                                       '"not_carried": {"/x": "why"}}')
    children._forward("/relay_a_high", '{"event": "ready", "node": "/relay_a_high"}')
    children._forward("/relay_a_high", "a line that is not JSON")
    merged = children.merge({"graph": "robot_a", "exports": [], "imports": [{"topic": "/robot_b/odom"}],
                             "not_carried": {}})
    assert merged["exports"] == [{"topic": "/control", "sent": 3, "process": "/relay_a_high"}]
    assert merged["imports"] == [{"topic": "/robot_b/odom"}] and merged["not_carried"] == {"/x": "why"}
    assert lines == ['{"event": "ready", "node": "/relay_a_high", "process": "/relay_a_high"}',
                     "a line that is not JSON"]   # stats are merged, not printed twice
