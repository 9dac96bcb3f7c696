"""Shared memory under faults (issue 46), with real processes: a rosmaster, micros_rt nodes on shared memory
(the harness turns it off for the rest of the suite; these tests turn it back on, the default users get),
forged XML-RPC calls from this process, and a /dev/shm of its own in a private mount namespace.
"""

from __future__ import annotations

import signal
import subprocess
import time
from typing import Any, Dict, List

import pytest

import harness

pytestmark = pytest.mark.integration

T = 60.0
FAULTS_PEER = str(harness.PEERS_DIR / "mrt_shm_faults.py")


def shm_env(master: harness.RosMaster) -> Dict[str, str]:
    return {**master.env, "MICROS_RT_DISABLE_SHM": "0"}  # the harness turns SHM off for the rest of the suite


def faults(mode: str, *args: Any) -> List[str]:
    return [harness.MICROS_RT_PYTHON, FAULTS_PEER, mode, *[str(a) for a in args]]


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM", "signal_shutdown"])
def test_a_node_publishing_in_a_tight_loop_over_shm_stops_within_2_s(ros_master: harness.RosMaster,
                                                                     spawn: harness.Spawner, stop: str) -> None:
    # rospy's signal handler ran micros_rt's shutdown hook in the thread it interrupted, which could be inside
    # ShmChannel.try_send holding the channel's lock that close() then waited for: a deadlock (3 of 6 runs)
    env = shm_env(ros_master)
    topic = f"/shm_faults/tight_{stop.lower()}"
    listener = spawn(faults("count", "--topic", topic), env, name="tight_listener")
    listener.wait_for("ready", T)
    extra = ["--stop-with", "signal_shutdown", "--after", 1.0] if stop == "signal_shutdown" else []
    for run in range(3):
        talker = spawn(faults("flood", "--topic", topic, *extra), env, name=f"tight_talker_{run}")
        flooding = talker.wait_for("flooding", T)
        assert flooding["connections"] == 1
        listener.wait_for(lambda e: e.get("event") == "count" and e["transports"] == ["SHM"], T)
        t0 = time.monotonic()
        if stop != "signal_shutdown":
            time.sleep(0.3)  # well inside the loop
            t0 = time.monotonic()
            talker.proc.send_signal(getattr(signal, stop))
        try:
            code = talker.proc.wait(10.0)  # the bound is 2 s; a hung node (the old code) fails here
        except subprocess.TimeoutExpired:
            pytest.fail(f"run {run}: the SHM talker still ran 10 s after {stop}: {talker.stderr_tail()}")
        took = time.monotonic() - t0
        print(f"run {run}: the SHM talker stopped {took:.2f} s after {stop}, exit code {code}")
        assert code == 0, talker.stderr_tail()
        if stop != "signal_shutdown":
            assert took < 2.0, (took, talker.stderr_tail())
        assert talker.count("stopped") == 1
