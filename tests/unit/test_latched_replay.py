"""Several latched messages in one rospy publication (the relay's import of several transient_local ROS 2 writers):
what a new TCPROS subscriber is sent, with rospy's own latch replay after the listener, as in
``rospy.topics._PublisherImpl.add_connection``."""

from __future__ import annotations

import threading
from typing import Any, List

from micros_rt.transports.tcpros.patches import _LatchedReplay


class _Impl:
    """rospy's per-topic publisher: ``publish(m, connection_override=c)`` latches ``m`` and writes it to ``c``."""

    def __init__(self) -> None:
        self.latch: Any = None

    def add_connection(self, listener: _LatchedReplay, sent: List[Any]) -> None:
        def publish_single(msg: Any) -> None:
            self.latch = msg
            sent.append(msg)

        listener.peer_subscribe("/t", None, publish_single)
        if self.latch is not None:
            sent.append(self.latch)


def test_a_new_subscriber_gets_every_sources_message_once_the_newest_last() -> None:
    impl, latched = _Impl(), {"w1": "a", "w2": "b", "w3": "c"}
    impl.latch = "c"
    listener = _LatchedReplay(impl, threading.Lock(), lambda: list(latched.values()))
    sent: List[Any] = []
    impl.add_connection(listener, sent)
    assert sent == ["a", "b", "c"] and impl.latch == "c"
    # the newest's source left: the newest of the others is latched in its place, the departed one never sent
    del latched["w3"]
    sent = []
    impl.add_connection(listener, sent)
    assert sent == ["a", "b"] and impl.latch == "b"
    latched.clear()
    sent = []
    impl.add_connection(listener, sent)
    assert sent == [] and impl.latch is None
