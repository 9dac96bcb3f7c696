"""The transport interface (micros_rt/transports/base.py): one contract that every reader and writer keeps,
run against real Cyclone endpoints in this process (loopback, this run's domain) and against pushed
readers (TCPROS, MQTT, UDP); the publication's two-phase send on a fake transport; the pushed reader's
queue rules; the one socket-marking helper; the one exception tree."""

from __future__ import annotations

import socket
import threading
import time
from typing import Any, Callable, Iterator, List, Optional, Tuple

import genpy
import pytest
from std_msgs.msg import Header, String

import harness

from micros_rt import MicrosRtError, TransportPriority
from micros_rt.qos import AdvertiseQoSOptions, priority_socket_priority, priority_tos
from micros_rt.qos.options import enforcers
from micros_rt.transports.base import (
    SOURCE_ORDER,
    TIME_FILTER,
    EndpointSpec,
    PushReader,
    TransportReader,
    TransportWriter,
)
from micros_rt.transports.marking import mark_socket

# -- the contract -------------------------------------------------------------------------------------
# A transport under contract: opens (writer, reader) on one topic, says when the reader hears the writer,
# and feeds the reader what the writer sent (for pushed transports, the I/O thread's job).
Pair = Tuple[TransportWriter, TransportReader, Callable[[], bool], Callable[[Any], None]]


def _dds_pair(topic: str, latch: bool = False) -> Pair:
    from micros_rt.transports.dds.backend import DDSBackend
    from micros_rt.transports.dds.participant import get_participant

    participant = get_participant()
    assert participant is not None
    backend = DDSBackend(participant, "transport_contract")
    spec = EndpointSpec(topic, String, 10, latch, {"graph": "contract", "node": "/contract"})
    writer = backend.open_writer(spec, AdvertiseQoSOptions())
    reader = backend.open_reader(spec, None, lambda: None, lambda _policy: None)

    def matched() -> bool:
        return bool(writer.matched_peers()) and bool(reader.matched_writers())

    return writer, reader, matched, writer.send


class _LoopWriter:
    """The writer side of a pushed transport, as its I/O thread sees it: ``send`` hands the message over."""

    protocol = "LOOP"

    def __init__(self, reader: PushReader) -> None:
        self.reader = reader
        self.closed = 0

    def prepare(self, msg: Any) -> Any:
        buf = __import__("io").BytesIO()
        msg.serialize(buf)  # genpy raises on a bad value, as TCPROS does before writing
        return msg

    def send(self, prepared: Any) -> None:
        self.reader.put(prepared)

    def close(self) -> None:
        self.closed += 1


def _pushed_pair(topic: str, latch: bool = False) -> Pair:
    reader = PushReader("LOOP", 10, lambda: None, blocking=False)
    writer = _LoopWriter(reader)
    return writer, reader, lambda: True, writer.send


TRANSPORTS = {"DDS": _dds_pair, "pushed": _pushed_pair}


@pytest.fixture(params=sorted(TRANSPORTS))
def pair(request: Any) -> Iterator[Pair]:
    topic = f"/micros_rt_contract_{request.param}_{int(time.time() * 1e6) % 10**9}"
    made = TRANSPORTS[request.param](topic)
    yield made
    made[0].close()
    made[1].close()


def test_contract_shapes(pair: Pair) -> None:
    writer, reader, _, _ = pair
    assert isinstance(writer, TransportWriter) and isinstance(reader, TransportReader)
    assert isinstance(writer.protocol, str) and writer.protocol == reader.protocol
    assert isinstance(reader.enforces, frozenset) and reader.enforces <= enforcers()


def test_contract_bad_value_refused_in_prepare_before_anything_is_sent(pair: Pair) -> None:
    writer, reader, matched, _ = pair
    harness.wait_until(matched, 10, message="writer and reader matched")
    with pytest.raises((genpy.SerializationError, TypeError, ValueError, AttributeError)):
        writer.prepare(String(data=123))
    assert reader.take(10) == []


def test_contract_messages_arrive_in_order_with_a_source_time(pair: Pair) -> None:
    writer, reader, matched, _ = pair
    harness.wait_until(matched, 10, message="writer and reader matched")
    for i in range(5):
        data = writer.prepare(String(data=f"m{i}"))
        assert data is not None
        writer.send(data)
    got: List[Any] = []

    def take() -> bool:
        got.extend(reader.take(256))
        return len(got) >= 5

    harness.wait_until(take, 10, message="five samples taken")
    assert [reader.decode(payload).data for payload, _info in got] == [f"m{i}" for i in range(5)]
    for _payload, info in got:
        assert info.valid_data is True and isinstance(info.source_timestamp, int)
    assert reader.take(10) == []


def test_contract_close_twice_is_harmless(pair: Pair) -> None:
    writer, reader, _, _ = pair
    writer.close()
    writer.close()
    reader.close()
    reader.close()


def test_dds_writer_encodes_nothing_while_no_reader_is_matched() -> None:
    from micros_rt.transports.dds.backend import DDSTopicWriter

    writer, reader, matched, _ = _dds_pair(f"/micros_rt_contract_unmatched_{int(time.time() * 1e6) % 10**9}")
    assert isinstance(writer, DDSTopicWriter)
    harness.wait_until(matched, 10, message="writer and reader matched")
    assert writer.prepare(String(data="somebody")) is not None
    reader.close()
    try:
        harness.wait_until(lambda: not writer.matched_peers(), 10, message="the reader gone")
        assert writer.prepare(String(data="nobody")) is None
    finally:
        writer.close()


def test_every_transport_implements_the_interface() -> None:
    """TCPROS, DDS, MQTT and the microcontroller link: the writer and reader classes have the methods."""
    from micros_rt.transports.tcpros import TcprosWriter
    from micros_rt.transports.dds.backend import DDSTopicReader, DDSTopicWriter

    for cls in (TcprosWriter, DDSTopicWriter):
        for name in ("prepare", "send", "close"):
            assert callable(getattr(cls, name)), (cls, name)
        assert isinstance(cls.protocol, str)
    assert DDSTopicReader.enforces == frozenset({TIME_FILTER, SOURCE_ORDER})  # Cyclone filters and orders
    assert PushReader.enforces == frozenset()  # TCPROS, MQTT, UDP: the subscription enforces everything


# -- publication: two phases over any writers ---------------------------------------------------------
class _FakeWriter:
    """httpx's MockTransport idea: a writer that records, refuses what it is told to refuse."""

    def __init__(self, protocol: str, refuse: Optional[str] = None, nobody: bool = False) -> None:
        self.protocol = protocol
        self.refuse = refuse
        self.nobody = nobody
        self.sent: List[Any] = []
        self.closed = False
        self._lock = threading.Lock()

    def lock(self) -> Any:
        return self._lock

    def prepare(self, msg: Any) -> Any:
        if self.refuse is not None and msg.data == self.refuse:
            raise genpy.SerializationError(f"{self.protocol} refuses {msg.data!r}")
        return None if self.nobody else (self.protocol, msg.data)

    def send(self, prepared: Any) -> None:
        self.sent.append(prepared)

    def close(self) -> None:
        self.closed = True


def _publication_with(*writers: _FakeWriter) -> Any:
    import rospy

    from micros_rt.core.publication import _Publication

    pub = _Publication("/fake", String, 10, False, AdvertiseQoSOptions(), tag={})
    pub.tcpros = writers[0]  # type: ignore[assignment]
    pub.writers = writers
    return pub, rospy


def test_a_message_one_writer_refuses_is_sent_by_none() -> None:
    first, second, third = _FakeWriter("TCPROS"), _FakeWriter("DDS"), _FakeWriter("MQTT", refuse="bad")
    pub, rospy = _publication_with(first, second, third)
    pub.publish(String(data="ok"))
    with pytest.raises(rospy.ROSSerializationException, match="MQTT refuses 'bad'"):
        pub.publish(String(data="bad"))
    assert first.sent == [("TCPROS", "ok")] and second.sent == [("DDS", "ok")] and third.sent == [("MQTT", "ok")]
    assert pub.statistics().published == 1


def test_a_writer_with_nobody_to_send_to_is_skipped() -> None:
    first, second = _FakeWriter("TCPROS", nobody=True), _FakeWriter("DDS")
    pub, _ = _publication_with(first, second)
    pub.publish(String(data="x"))
    assert first.sent == [] and second.sent == [("DDS", "x")]


# -- pushed readers -----------------------------------------------------------------------------------
def test_pushed_reader_from_a_shared_thread_never_waits_and_counts_what_it_drops() -> None:
    wakes: List[int] = []
    reader = PushReader("MQTT", 3, lambda: wakes.append(1), blocking=False)
    t0 = time.monotonic()
    for i in range(10):
        reader.put(String(data=str(i)))
    assert time.monotonic() - t0 < 1.0
    assert [m.data for m, _ in reader.take(100)] == ["7", "8", "9"]  # the newest queue_size, as ROS keeps
    assert reader.dropped == 7 and len(wakes) == 10


def test_pushed_reader_unbounded_for_lossless_subscriptions() -> None:
    reader = PushReader("MQTT", None, lambda: None, blocking=False)
    for i in range(1000):
        reader.put(i)
    assert len(reader.take(2000)) == 1000 and reader.dropped == 0


def test_pushed_reader_of_a_links_own_thread_waits_for_room_and_close_releases_it() -> None:
    reader = PushReader("TCPROS", 2, lambda: None, blocking=True)
    reader.put("a")
    reader.put("b")
    done = threading.Event()

    def third() -> None:
        reader.put("c")  # waits: back-pressure to this link
        done.set()

    threading.Thread(target=third, daemon=True).start()
    assert not done.wait(0.3)
    assert [m for m, _ in reader.take(1)] == ["a"]
    assert done.wait(10)
    assert [m for m, _ in reader.take(10)] == ["b", "c"] and reader.dropped == 0
    reader.put("d")
    reader.put("e")
    blocked = threading.Thread(target=reader.put, args=("f",), daemon=True)
    blocked.start()
    reader.close()
    blocked.join(10)
    assert not blocked.is_alive()


def test_pushed_sample_carries_the_source_time_and_link() -> None:
    reader = PushReader("TCPROS", 2, lambda: None, blocking=True)
    msg = Header(stamp=genpy.Time(5, 6))
    reader.put(msg, 5_000_000_006, "http://host:1/")
    [(got, info)] = reader.take(1)
    assert got is msg and info.source_timestamp == 5_000_000_006 and info.publication_handle == "http://host:1/"


# -- marking, exceptions ------------------------------------------------------------------------------
@pytest.mark.parametrize("family", [socket.AF_INET, socket.AF_INET6])
def test_mark_socket_sets_dscp_and_priority_per_family(family: int) -> None:
    with socket.socket(family, socket.SOCK_DGRAM) as s:
        assert mark_socket(s, TransportPriority.HIGH)
        level, opt = ((socket.IPPROTO_IP, socket.IP_TOS) if family == socket.AF_INET
                      else (socket.IPPROTO_IPV6, socket.IPV6_TCLASS))
        assert s.getsockopt(level, opt) == priority_tos(TransportPriority.HIGH)
        assert s.getsockopt(socket.SOL_SOCKET, socket.SO_PRIORITY) == priority_socket_priority(TransportPriority.HIGH)
        assert not mark_socket(s, TransportPriority.NORMAL)       # NORMAL leaves it as it is
        assert s.getsockopt(level, opt) == priority_tos(TransportPriority.HIGH)
        assert mark_socket(s, TransportPriority.NORMAL, force=True)
        assert s.getsockopt(level, opt) == 0


def test_unix_sockets_carry_no_tos() -> None:
    a, b = socket.socketpair()
    with a, b:
        assert not mark_socket(a, TransportPriority.HIGH)


def test_transport_errors_are_in_the_one_exception_tree() -> None:
    from micros_rt.transports.mcu.errors import McuConfigError, WireError
    from micros_rt.transports.mqtt.client import MqttConfigError
    from micros_rt.transports.mqtt.codec import CodecError
    from micros_rt.transports.mqtt.params import ParamsError

    for cls in (MqttConfigError, CodecError, ParamsError, McuConfigError, WireError):
        assert issubclass(cls, MicrosRtError) and issubclass(cls, ValueError), cls


# -- subscription: one admission path, whatever the transport ------------------------------------------
class _FilteringReader(PushReader):
    """A fake pushed transport that says it applies the time filter itself (as Cyclone does)."""

    enforces = frozenset({TIME_FILTER})


def _subscription(options: Any, depth: Optional[int] = 100) -> Any:
    from micros_rt.core.subscription import _Subscription
    from micros_rt.negotiation import TransportHints

    sub = _Subscription("/admission", String, depth, options, TransportHints().tcp(), tag={}, graph="g")
    got: List[Any] = []
    sub.callbacks = ((lambda msg: got.append(msg.data), None),)
    sub.thread.start()  # the delivery thread only: no rospy registration
    return sub, got


def test_the_subscription_applies_the_time_filter_a_reader_does_not() -> None:
    from micros_rt.qos import SubscribeQoSOptions

    sub, got = _subscription(SubscribeQoSOptions(time_filter_duration=30.0))
    filtering = _FilteringReader("FAKE", 100, sub.inbox.wake, blocking=False)
    sub.pushed = sub.pushed + (filtering,)
    try:
        for i in range(5):
            sub.tcp_in.put(String(data=f"tcp {i}"))     # TCPROS enforces nothing: one per 30 s passes
        harness.wait_until(lambda: sub.statistics().received == 5, 10, message="five TCPROS messages taken")
        for i in range(5):
            filtering.put(String(data=f"fake {i}"))     # the transport filtered already: all delivered
        harness.wait_until(lambda: len(got) == 6, 10, message="the filtered transport's five delivered")
        assert got == ["tcp 0"] + [f"fake {i}" for i in range(5)]
        stats = sub.statistics()
        assert (stats.received, stats.delivered, stats.dropped_filtered) == (10, 6, 4)
    finally:
        sub.close()


def test_drops_of_a_shared_thread_reader_are_in_the_subscriptions_statistics() -> None:
    from micros_rt.qos import SubscribeQoSOptions

    sub, got = _subscription(SubscribeQoSOptions(), depth=2)
    feed = PushReader("MQTT", 2, lambda: None, blocking=False)  # not woken: its queue overflows first
    sub.pushed = sub.pushed + (feed,)
    try:
        for i in range(7):
            feed.put(String(data=str(i)))
        sub.inbox.wake()
        harness.wait_until(lambda: len(got) == 2, 10, message="the newest two delivered")
        assert got == ["5", "6"]
        stats = sub.statistics()
        assert (stats.received, stats.delivered, stats.dropped_queue_full) == (7, 2, 5)
    finally:
        sub.close()


def test_node_shutdown_closes_the_profile_transports_it_opened(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys
    import types

    from micros_rt.transports import base

    closed: List[str] = []
    fake = types.ModuleType("micros_rt_fake_profile_transport")
    fake.close_profile_backend = lambda: closed.append("fake")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, fake.__name__, fake)
    monkeypatch.setattr(base, "PROFILE_BACKENDS", {"fake": fake.__name__, "never_imported": "micros_rt_not_loaded"})
    base.close_profile_backends()
    assert closed == ["fake"] and "micros_rt_not_loaded" not in sys.modules


def test_the_mqtt_profile_transport_says_how_to_close_it() -> None:
    import micros_rt.transports.mqtt

    from micros_rt.transports.base import PROFILE_BACKENDS

    assert PROFILE_BACKENDS["mqtt"] == "micros_rt.transports.mqtt"
    micros_rt.transports.mqtt.close_profile_backend()   # none was made: harmless
    micros_rt.transports.mqtt.close_profile_backend()
