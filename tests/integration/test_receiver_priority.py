"""Priority in the receiver (core/threadprio.py): a node that receives a HIGH control topic and a LOW camera
whose callbacks keep its CPU busy runs the control topic's delivery thread at a higher OS priority than the
camera's, and the interpreter switches threads every 1 ms instead of 5 while it receives a HIGH topic.

Loopback, real processes: tests/peers/mrt_link.py publishes /control (HIGH, 1 kHz) and /image (LOW, 640x480,
30 Hz); its subscriber computes 20 ms in Python in every image callback (the GIL held: a CPU-bound node)
and reports each delivery thread's nice value and the switch interval it ran with.
"""

from __future__ import annotations

import os
from typing import Any, Dict, List

import pytest

import harness

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

LINK = str(harness.PEERS_DIR / "mrt_link.py")


def link(*args: Any) -> List[str]:
    return [harness.MICROS_RT_PYTHON, LINK, *[str(a) for a in args]]


def _run(spawn: harness.Spawner, env: Dict[str, str]) -> Dict[str, Any]:
    sub = spawn(link("sub", "--seconds", 90, "--image-work-ms", 20), env=env, name="sub")
    sub.wait_for("ready", 60)
    pub = spawn(link("pub", "--seconds", 4), env=env, name="pub")
    pub.wait_for("ready", 90)
    published = pub.wait_for("published", 90)
    summary: Dict[str, Any] = sub.wait_for("summary", 120)
    print(f"\nreceiver priority {env.get('MICROS_RT_RECEIVE_PRIORITY', 'on')}: control {summary['control']} of "
          f"{published['control']}, p50 {summary['p50_ms']:.2f} ms, p99 {summary['p99_ms']:.2f} ms; images "
          f"{summary['image']}; nice {summary['nice']}, switch interval {summary['switch_interval']}")
    assert summary["transports"] == ["DDS"], summary
    assert summary["control"] >= 0.99 * published["control"], (summary, published)
    return summary


def test_high_topics_delivery_thread_runs_first(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    summary = _run(spawn, dict(ros_master.env))
    # root (CI, this machine) may lower a nice value; an unprivileged node leaves HIGH at 0 and says so
    high = -5 if os.geteuid() == 0 else 0
    assert summary["nice"] == {"/control": high, "/image": 5}, summary
    assert abs(summary["switch_interval"] - 0.001) < 1e-7, summary


def test_receiver_priority_can_be_turned_off(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    summary = _run(spawn, {**ros_master.env, "MICROS_RT_RECEIVE_PRIORITY": "0"})
    assert summary["nice"] == {"/control": 0, "/image": 0}, summary
    assert abs(summary["switch_interval"] - 0.005) < 1e-7, summary
