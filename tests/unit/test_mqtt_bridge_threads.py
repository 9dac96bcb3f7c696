"""The MQTT bridge hands each MQTT topic's messages to a worker of its own: advertising a ROS topic (a
master registration, then a wait of up to 3 s for the subscribers the master lists) no longer runs on
paho's network thread, which every MQTT topic of the bridge shares."""

from __future__ import annotations

import threading
import time
import types
from typing import Any, List, cast

import pytest
from std_msgs.msg import String

import harness

from micros_rt.bridges.mqtt import bridge as bridge_module
from micros_rt.transports.mqtt import codec
from micros_rt.bridges.mqtt.params import Mqtt2RosParams


class _SlowMasterNodeHandle:
    """advertise() of topic /slow waits at a gate, as a registration with an unreachable master does."""

    def __init__(self) -> None:
        self.gate = threading.Event()
        self.published: List[Any] = []

    def advertise(self, topic: str, cls: type, queue_size: int, latch: bool = False) -> Any:
        if topic == "/slow":
            self.gate.wait(30)
        return types.SimpleNamespace(publish=lambda msg: self.published.append((topic, msg.data)),
                                     unregister=lambda: None)


def test_a_topic_whose_advertise_waits_does_not_hold_another_topic(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bridge_module, "_await_subscribers", lambda pub: None)
    nh = _SlowMasterNodeHandle()
    fake_bridge = cast(Any, types.SimpleNamespace(nh=nh, problems=bridge_module._Problems()))
    slow = bridge_module._Mqtt2Ros(fake_bridge, Mqtt2RosParams(mqtt_topic="slow", ros_topic="/slow"))
    fast = bridge_module._Mqtt2Ros(fake_bridge, Mqtt2RosParams(mqtt_topic="fast", ros_topic="/fast"))
    string_type = codec.encode_msg_type(codec.RosMsgType.of(String, stamped=False))

    def payload(text: str) -> bytes:
        return codec.encode_ros_payload(_serialized(String(data=text)), wire=codec.WireGeneration.V2)

    # what paho's network thread does, in arrival order: it must never wait
    t0 = time.monotonic()
    slow.feed_type("mqtt_client/ros_msg_type/slow", string_type)
    slow.feed_data("slow", payload("s0"))
    fast.feed_type("mqtt_client/ros_msg_type/fast", string_type)
    for i in range(3):
        fast.feed_data("fast", payload(f"f{i}"))
    assert time.monotonic() - t0 < 1.0
    harness.wait_until(lambda: len(nh.published) == 3, 10, message="the fast topic's three published")
    assert nh.published == [("/fast", "f0"), ("/fast", "f1"), ("/fast", "f2")]   # /slow still registering
    nh.gate.set()
    harness.wait_until(lambda: ("/slow", "s0") in nh.published, 10, message="the slow topic's message, in order")
    slow.worker.close()
    fast.worker.close()


def test_a_full_backlog_drops_the_oldest_data_and_keeps_type_announcements(monkeypatch: pytest.MonkeyPatch) -> None:
    reports: List[int] = []
    worker = bridge_module._TopicWorker("t", reports.append)
    gate = threading.Event()
    done: List[Any] = []
    def busy() -> None:
        gate.wait(30)

    worker.put(busy)                                             # the worker is busy
    harness.wait_until(lambda: not worker._items, 10)
    worker.put(done.append, "type", droppable=False)
    for i in range(bridge_module.WORKER_BACKLOG + 5):
        worker.put(done.append, i)
    # 1 + 1,005 waiting, 1,000 kept: the 6 oldest data dropped, the type announcement never
    assert worker.dropped == 6 and reports[-1] == 6
    gate.set()
    harness.wait_until(lambda: len(done) == bridge_module.WORKER_BACKLOG, 10)
    assert done[0] == "type" and done[1] == 6 and done[-1] == bridge_module.WORKER_BACKLOG + 4
    worker.close()


def _serialized(msg: Any) -> bytes:
    import io

    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()
