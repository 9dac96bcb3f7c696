"""What adding a transport takes, measured: a toy shared-memory transport plugged in the way a profile transport
is (MQTT's way), end to end through a real publication and subscription of the core.

The toy lives in this file. Plugging it in took: its module (here), one entry in
``micros_rt.transports.base.PROFILE_BACKENDS`` (monkeypatched here) and, for a YAML profile to carry its section,
``micros_rt.qos.profiles`` (a test profile object stands in here). The core (publication, send queues, subscription,
admission, statistics) was not touched: the toy's writer is one more writer of the publication's two-phase
send, its feed one more pushed reader of the subscription's one admission path.
"""

from __future__ import annotations

import sys
import time
import types
from typing import Any, Callable, Dict, List, Optional

import pytest
import rospy
from std_msgs.msg import String

from contract.checks import wait_until
from contract.fake_transport import FakeBus, FakeWriter
from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.transports.base import PROFILE_BACKENDS, EndpointSpec, profile_backends

SHM = "TOY_SHM"  # not the real SHM transport (micros_rt.transports.shm)


class _ToyFeed:
    """The toy's reader end as the core sees a profile transport's feed: ``deliver(msg)`` per message."""

    protocol = SHM

    def __init__(self, bus: FakeBus, spec: EndpointSpec, deliver: Callable[[Any], None]) -> None:
        self._reader = bus.reader(spec.topic, spec.data_class, None, self._arrived)
        self._deliver = deliver

    def _arrived(self) -> None:
        for msg, _info in self._reader.take(256):
            msg._connection_header = {"transport": SHM}
            self._deliver(msg)

    def transports(self) -> Dict[str, str]:
        return {"shm://toy": SHM}

    def close(self) -> None:
        self._reader.close()


class ToyShm:
    """A shared-memory transport for the topics its profile section lists (one segment per process: a bus)."""

    def __init__(self, topics: List[str]) -> None:
        self.topics = set(topics)
        self.bus = FakeBus()

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> Optional[FakeWriter]:
        if spec.topic not in self.topics:
            return None
        writer = self.bus.writer(spec.topic)
        writer.protocol = SHM
        return writer

    def open_feed(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                  deliver: Callable[[Any], None]) -> Optional[_ToyFeed]:
        return _ToyFeed(self.bus, spec, deliver) if spec.topic in self.topics else None


@pytest.fixture
def toy(monkeypatch: pytest.MonkeyPatch) -> ToyShm:
    """The toy registered as the profile section ``shm`` (the one line a new transport adds to base.py)."""
    module = types.ModuleType("toy_shm_transport")
    made: List[ToyShm] = []

    def profile_backend(profile: Any, *, graph: str, node: str) -> ToyShm:
        if not made:
            made.append(ToyShm(profile.shm["topics"]))
        return made[0]

    module.profile_backend = profile_backend  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(PROFILE_BACKENDS, "shm", module.__name__)
    profile = types.SimpleNamespace(shm={"topics": ["/toy/chatter"]}, mqtt=None)
    backends = profile_backends(profile, graph="g", node="/toy")
    assert len(backends) == 1 and isinstance(backends[0], ToyShm)
    return backends[0]


def test_a_toy_shared_memory_transport_runs_end_to_end_through_publication_and_subscription(toy: ToyShm) -> None:
    from micros_rt.core.publication import _Publication
    from micros_rt.core.subscription import _Subscription
    from micros_rt.negotiation import TransportHints

    got: List[Any] = []
    # the core's own endpoints, untouched; no master: rospy registers nothing until a node starts
    sub = _Subscription("/toy/chatter", String, 10, SubscribeQoSOptions(time_filter_duration=0.2,
                                                                         ordered_by_sending_timestamp=False),
                        TransportHints().tcp(), tag={}, graph="g", extra=(toy,))
    sub.callbacks = ((got.append, None),)
    sub.start()
    pub = _Publication("/toy/chatter", String, 10, False, AdvertiseQoSOptions(), tag={}, extra=(toy,))
    pub.start()
    try:
        assert [w.protocol for w in pub.writers] == ["TCPROS", SHM]
        assert [r.protocol for r in sub.pushed] == ["TCPROS", SHM]
        for i in range(5):
            pub.publish(String(data=f"m{i}"))  # one burst: the subscription's time filter lets the first through
        wait_until(lambda: sub.statistics().received == 5, 10, "five messages over the toy transport")
        time.sleep(0.25)  # past the 0.2 s filter period (the duration under test, not a wait for an event)
        pub.publish(String(data="after"))
        wait_until(lambda: len(got) == 2, 10, "the message after the filter period")
        assert [m.data for m in got] == ["m0", "after"]
        assert all(m._connection_header["transport"] == SHM for m in got)
        stats = sub.statistics()
        assert (stats.received, stats.delivered, stats.dropped_filtered) == (6, 2, 4)
        assert pub.statistics().published == 6
        with pytest.raises(rospy.ROSSerializationException):
            pub.publish(String(data=7))  # refused in prepare: nothing sent on any transport
        assert pub.statistics().published == 6 and sub.statistics().received == 6
    finally:
        pub.close()
        sub.close()
