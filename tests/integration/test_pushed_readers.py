"""Pushed readers (TCPROS, MQTT) each have their own queue: a slow subscription of a process must not stall
another topic fed by the same I/O thread. Real mosquitto, two real masters, micros_rt peers."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Dict

import harness
from helpers import mrt
from mqtt_broker import MosquittoBroker, write_params

N = 100


def test_slow_mqtt_subscription_does_not_stall_another_mqtt_topic(
        ros_master: harness.RosMaster, fresh_master: harness.RosMaster, spawn: harness.Spawner,
        tmp_path: Path) -> None:
    # paho runs every MQTT topic of a process on one network thread. Before each feed had a queue of its
    # own, a full inbox of the slow topic made that thread wait, so the fast topic got one message per slow
    # callback (0.5 s): 100 fast messages took ~50 s and the slow callback ran ~100 times meanwhile.
    with MosquittoBroker(tmp_path / "broker") as broker:
        mqtt: Dict[str, Any] = {"broker": {"host": broker.host, "port": broker.port}, "topics": {"/pr/*": {}}}
        path = write_params(tmp_path / "profile.yaml", {"mqtt": mqtt})
        env_a = dict(ros_master.env, MICROS_RT_QOS_PROFILE=str(path))
        env_b = dict(fresh_master.env, MICROS_RT_QOS_PROFILE=str(path))

        listener = spawn(mrt("listen", "--topic", "/pr/fast", "--slow-topic", "/pr/slow", "--slow-sleep", 0.5,
                             "--duration", 120, "--exit-after", N, "--node-name", "pr_listener"), env_b,
                         name="listener")
        harness.wait_until(lambda: sum("is fed from MQTT topic" in e.get("text", "")
                                       for e in listener.events("log")) >= 2, 30)
        time.sleep(0.5)                                   # the broker has processed the SUBSCRIBEs

        slow = spawn(mrt("talk", "--topic", "/pr/slow", "--count", N, "--rate", 50, "--node-name", "pr_slow"),
                     env_a, name="slow_talker")
        fast = spawn(mrt("talk", "--topic", "/pr/fast", "--count", N, "--rate", 50, "--node-name", "pr_fast"),
                     env_a, name="fast_talker")

        got = listener.wait_for_count("recv", N, timeout=90)
        slow_handled = len(listener.events("slow_recv"))
        assert [e["data"] for e in got] == [f"hello {i}" for i in range(N)]
        assert {e["transport"] for e in got} == {"MQTT"}
        # 100 fast messages at 50 Hz take ~2 s to send: the slow callback (2 per second) ran a few times
        # meanwhile, not once per fast message
        assert 1 <= slow_handled < N // 3, slow_handled

        assert fast.wait(timeout=60) == 0, fast.stderr_tail()
        assert slow.wait(timeout=60) == 0, slow.stderr_tail()
        stats = listener.wait_for("slow_statistics", timeout=30)
        # the slow topic kept the newest (queue_size=1) and counted every message it dropped
        assert stats["dropped_queue_full"] > 0, stats
        # every message received is delivered, dropped (counted) or still queued behind the running callback
        accounted = stats["delivered"] + stats["dropped_queue_full"]
        assert stats["received"] <= N and 0 <= stats["received"] - accounted <= 2, stats
        print(f"fast topic: {len(got)} of {N} in order over MQTT while the slow callback ran {slow_handled} times; "
              f"slow topic statistics: {stats}")
