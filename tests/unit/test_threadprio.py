"""Receiver priority's pure parts: nice values per transport priority, the process's switch interval while
HIGH topics are received, and setting a thread's nice value (Linux: per thread)."""

from __future__ import annotations

import os
import sys
import threading
from typing import List

import pytest

from micros_rt.core import threadprio
from micros_rt.core.threadprio import HIGH_SWITCH_INTERVAL, ReceivePriority, enabled, nice_for, set_thread_nice
from micros_rt.qos import TransportPriority as P


def test_nice_values_follow_the_transport_priority() -> None:
    assert [nice_for(p) for p in P] == [5, 5, 5, 0, -5, -5, -5]


def test_switch_interval_is_short_while_any_high_topic_is_received() -> None:
    saved = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.005)
        rp = ReceivePriority()
        rp.enter_high()
        rp.enter_high()
        assert sys.getswitchinterval() == HIGH_SWITCH_INTERVAL and rp.high == 2
        rp.leave_high()
        assert sys.getswitchinterval() == HIGH_SWITCH_INTERVAL  # one HIGH topic is still received
        rp.leave_high()
        assert sys.getswitchinterval() == 0.005 and rp.high == 0
        rp.leave_high()  # more leaves than enters: harmless
        assert rp.high == 0
    finally:
        sys.setswitchinterval(saved)


def test_a_nodes_own_switch_interval_is_not_undone() -> None:
    saved = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.005)
        rp = ReceivePriority()
        rp.enter_high()
        sys.setswitchinterval(0.0002)  # the node chose its own meanwhile
        rp.leave_high()
        assert sys.getswitchinterval() == pytest.approx(0.0002)
        sys.setswitchinterval(0.0005)  # already shorter than micros_rt's: left as it is
        rp.enter_high()
        assert sys.getswitchinterval() == pytest.approx(0.0005)
        rp.leave_high()
    finally:
        sys.setswitchinterval(saved)


@pytest.mark.parametrize("nice", [5, -5])
def test_set_thread_nice_changes_only_that_thread(nice: int) -> None:
    got: List[int] = []

    def body() -> None:
        got.append(set_thread_nice(nice))
        got.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))

    t = threading.Thread(target=body)
    t.start()
    t.join()
    expected = nice if nice > 0 or os.geteuid() == 0 else 0
    assert got == [expected, expected]
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == 0  # this thread untouched


def test_environment_switch() -> None:
    assert enabled({}) and enabled({"MICROS_RT_RECEIVE_PRIORITY": "1"})
    for off in ("0", "off", "false", "No"):
        assert not enabled({"MICROS_RT_RECEIVE_PRIORITY": off})
    assert threadprio.RECEIVE_PRIORITY.high == 0
