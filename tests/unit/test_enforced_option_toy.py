"""A toy enforced option is two pieces: its catalogue entry (:data:`micros_rt.qos.options.OPTIONS`, with its field on
the option class, as the catalogue's own toy test adds one) and its enforcer (an
:class:`~micros_rt.qos.enforcement.Admission`). With nothing else touched, a real subscription's delivery thread
enforces it on what a transport hands over, counts its drops under the entry's counter in ``statistics()``, and does
not run it at all where the option asks for nothing."""

from __future__ import annotations

import dataclasses
import time
from typing import Any, List

import pytest
from geometry_msgs.msg import PointStamped

import harness
from micros_rt.negotiation import TransportHints
from micros_rt.qos import SubscribeQoSOptions, options
from micros_rt.qos.enforcement import Admission
from micros_rt.qos.options import OPTIONS, QoSOption, drop_counters


class RequireStamp(Admission):
    """The toy's enforcer: a message with no source stamp (no sending time, no Header stamp) is dropped."""

    __slots__ = ("enabled",)
    rank = 40

    def __init__(self, enabled: bool) -> None:
        super().__init__()
        self.enabled = enabled

    def active(self) -> bool:
        return self.enabled

    def check(self, sent_ns: int, source_ns: int, qos: Any) -> bool:
        return source_ns > 0


#: the toy's catalogue entry
TOY = QoSOption("require_stamp", "subscribe", "bool", "toy: drop messages that carry no source stamp",
                enforcer="require_stamp", counter="dropped_unstamped", admission=RequireStamp)


@dataclasses.dataclass(frozen=True)
class ToySubscribe(SubscribeQoSOptions):
    require_stamp: bool = False


@pytest.fixture
def toy_option(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(options, "OPTIONS", OPTIONS + (TOY,))
    monkeypatch.setitem(options.OPTION_CLASSES, "subscribe", ToySubscribe)
    monkeypatch.setattr(ToySubscribe, "_KEYS", options._field_keys(ToySubscribe, "subscribe"))


def _stamped(i: int, secs: int) -> PointStamped:
    msg = PointStamped()
    msg.header.frame_id = f"m{i}"
    msg.header.stamp.secs = secs
    return msg


def test_a_toy_enforced_option_is_enforced_and_counted_end_to_end(toy_option: None) -> None:
    from micros_rt.core.subscription import _Subscription

    assert drop_counters()[-1] == "dropped_unstamped"  # the graph tool and the relay read it from here
    sub = _Subscription("/toy/enforced", PointStamped, 100, ToySubscribe(require_stamp=True,
                                                                         ordered_by_sending_timestamp=False),
                        TransportHints().tcp(), tag={}, graph="g")
    got: List[str] = []
    sub.callbacks = ((lambda m: got.append(m.header.frame_id), None),)
    sub.thread.start()  # the delivery thread only: no rospy registration
    try:
        now = int(time.time())
        for i, secs in enumerate((0, now, 0, 0, now)):  # TCPROS carries no sending time: the Header's stamp
            sub.tcp_in.put(_stamped(i, secs))
        harness.wait_until(lambda: sub.statistics().received == 5, 10, message="five messages taken")
        stats = sub.statistics()
        assert got == ["m1", "m4"]
        assert (stats.received, stats.delivered, stats.dropped_unstamped) == (5, 2, 3)
        assert ("dropped_unstamped", 3) in stats.extra and sub.dropped_unstamped == 3
    finally:
        sub.close()


def test_a_toy_enforced_option_not_asked_for_is_not_run(toy_option: None) -> None:
    from micros_rt.core.subscription import _Subscription

    sub = _Subscription("/toy/not_asked", PointStamped, 100, ToySubscribe(ordered_by_sending_timestamp=False),
                        TransportHints().tcp(), tag={}, graph="g")
    got: List[str] = []
    sub.callbacks = ((lambda m: got.append(m.header.frame_id), None),)
    sub.thread.start()
    try:
        assert not any(isinstance(check, RequireStamp) for check in sub._checks)
        for i in range(3):
            sub.tcp_in.put(_stamped(i, 0))
        harness.wait_until(lambda: len(got) == 3, 10, message="three unstamped messages delivered")
        assert sub.statistics().dropped_unstamped == 0
    finally:
        sub.close()
