"""The transport contract: one set of checks that every transport's writer and reader pass.

A :class:`Pair` is one transport's writer and reader on one topic (plus what the checks need to know of it);
each ``check_*`` function takes one and raises ``AssertionError`` (in words) when the transport breaks the
contract of :mod:`micros_rt.transports.base`. The same functions run in the pytest process
(``test_contract.py``: the fake in-memory transport, DDS on loopback, the microcontroller UDP link, MQTT through
a real mosquitto) and in a rospy node (``tcpros_child.py``, for TCPROS, which needs a master). No pytest here.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, List, Optional

import genpy
from geometry_msgs.msg import PointStamped

from micros_rt.exceptions import MicrosRtError
from micros_rt.qos import SubscribeQoSOptions
from micros_rt.qos.options import enforcers
from micros_rt.transports.base import LIFESPAN, SOURCE_ORDER, TIME_FILTER, PushReader, TransportReader, TransportWriter

__all__ = ["CHECKS", "Pair", "message", "wait_until"]

PROBE = "probe"  # frame_id of the messages a pair's ``matched`` may send (MQTT): the checks ignore them


@dataclasses.dataclass
class Pair:
    """One transport under contract."""

    name: str
    writer: TransportWriter
    reader: TransportReader
    #: True once the reader hears the writer
    matched: Callable[[], bool]
    #: a writer on a topic nobody reads, for transports that know their receivers (prepare -> None); None
    #: for transports that cannot know (a UDP board, an MQTT broker): prepare always returns a payload
    lonely_writer: Optional[Callable[[], TransportWriter]]
    #: runs the transport's decoding step on malformed wire bytes (it must raise a MicrosRtError)
    corrupt: Callable[[], Any]
    #: a second reader of the topic with a time filter of ``period`` s, for readers declaring TIME_FILTER
    filtering_reader: Optional[Callable[[float], TransportReader]] = None
    cleanup: Callable[[], None] = lambda: None
    #: sends a message its transport stamps as written ``age`` s ago, for transports that carry the write
    #: time (SHM, as DDS: lifespan counts from the write, not from the Header stamp); None: the Header stamp
    #: is what a pushed reader's lifespan goes by, so the message's stamp is made old
    send_stale: Optional[Callable[[PointStamped, float], None]] = None


def wait_until(predicate: Callable[[], Any], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.005)


def message(i: int, *, age: float = 0.0) -> PointStamped:
    msg = PointStamped()
    msg.header.stamp = genpy.Time.from_sec(time.time() - age)
    msg.header.frame_id = f"m{i}"
    msg.point.x, msg.point.y, msg.point.z = i + 0.5, -i * 2.0, 1e-3 * i
    return msg


def _take(reader: TransportReader, n: int, timeout: float = 10.0) -> List[Any]:
    """``n`` messages (decoded, probes left out), oldest first."""
    got: List[Any] = []

    def more() -> bool:
        for payload, info in reader.take(256):
            if getattr(info, "valid_data", True):
                msg = reader.decode(payload)
                if msg.header.frame_id != PROBE:
                    got.append(msg)
        return len(got) >= n

    wait_until(more, timeout, f"{n} messages at the {reader.protocol} reader (got {len(got)})")
    return got


def _quiet(reader: TransportReader) -> List[Any]:
    """What else the reader holds now (probes left out)."""
    return [m for m in (reader.decode(p) for p, i in reader.take(256) if getattr(i, "valid_data", True))
            if m.header.frame_id != PROBE]


def _same(sent: PointStamped, got: PointStamped) -> bool:
    return (got.header.frame_id, got.header.stamp, got.point) == (sent.header.frame_id, sent.header.stamp, sent.point)


# -- the checks -------------------------------------------------------------------------------------------
def check_interface_is_declared(pair: Pair) -> None:
    """Both ends are the interface's, of one protocol; the reader says which QoS it enforces itself."""
    writer, reader = pair.writer, pair.reader
    assert isinstance(writer, TransportWriter), f"{type(writer).__name__} lacks prepare/send/close"
    assert isinstance(reader, TransportReader), f"{type(reader).__name__} lacks take/decode/close/enforces"
    assert writer.protocol == reader.protocol, (writer.protocol, reader.protocol)
    assert isinstance(reader.enforces, frozenset) and reader.enforces <= enforcers(), reader.enforces


def check_prepare_is_none_without_receivers_else_a_payload(pair: Pair) -> None:
    if pair.lonely_writer is not None:
        lonely = pair.lonely_writer()
        try:
            assert lonely.prepare(message(0)) is None, "prepare() encoded a message nobody can receive"
        finally:
            lonely.close()
    wait_until(pair.matched, 20, "the reader to hear the writer")
    assert pair.writer.prepare(message(1)) is not None


def check_send_delivers_what_was_prepared_equal_and_in_order(pair: Pair) -> None:
    wait_until(pair.matched, 20, "the reader to hear the writer")
    _quiet(pair.reader)
    sent = [message(i) for i in range(5)]
    for msg in sent:
        prepared = pair.writer.prepare(msg)
        assert prepared is not None
        pair.writer.send(prepared)
    got = _take(pair.reader, 5)
    for want, have in zip(sent, got):
        assert _same(want, have), f"sent {want.header.frame_id} {want.point}, received {have.header.frame_id} {have.point}"
    assert [m.header.frame_id for m in got] == [f"m{i}" for i in range(5)]
    time.sleep(0.05)  # nothing more may come: no duplicate (a bounded look, not a wait for an event)
    assert _quiet(pair.reader) == []


def check_a_bad_value_is_refused_before_anything_is_sent(pair: Pair) -> None:
    wait_until(pair.matched, 20, "the reader to hear the writer")
    _quiet(pair.reader)
    bad = message(9)
    bad.header.frame_id = 123
    try:
        prepared = pair.writer.prepare(bad)
        if prepared is not None:
            pair.writer.send(prepared)  # TCPROS: rospy serializes in send, before writing a byte
    except genpy.SerializationError as exc:
        assert "frame_id" in str(exc), f"the error does not name the field: {exc}"
    else:
        raise AssertionError("a string field holding 123 was not refused")
    good = pair.writer.prepare(message(10))
    assert good is not None
    pair.writer.send(good)
    assert [m.header.frame_id for m in _take(pair.reader, 1)] == ["m10"]


def check_malformed_wire_input_raises_a_micros_rt_error_in_words(pair: Pair) -> None:
    try:
        pair.corrupt()
    except MicrosRtError as exc:
        assert isinstance(exc, ValueError), f"{type(exc).__name__} is not also a ValueError"
        assert len(str(exc)) >= 20, f"too terse to act on: {exc!r}"
    else:
        raise AssertionError("malformed bytes were decoded without an error")


def check_what_the_reader_does_not_enforce_the_core_applies(pair: Pair) -> None:
    """The subscription's one admission path: time filter unless the reader applies it, lifespan always
    (no transport applies a subscriber's own lifespan); and a reader declaring TIME_FILTER really filters."""
    from micros_rt.core.subscription import _Subscription
    from micros_rt.negotiation import TransportHints

    reader = pair.reader
    options = SubscribeQoSOptions(time_filter_duration=30.0, ordered_by_sending_timestamp=False)
    sub = _Subscription("/contract/admission", PointStamped, 100, options, TransportHints().tcp(),
                        tag={}, graph="contract")
    sub.lifespan = 1.0
    try:
        now = time.time_ns()
        admitted = [sub._admit_enforced(reader, now, None) for _ in range(3)]
        if TIME_FILTER in reader.enforces:
            assert admitted == [True] * 3 and sub.dropped_filtered == 0, "the core filtered again"
        else:
            assert admitted == [True, False, False] and sub.dropped_filtered == 2, admitted
        sub.time_filter.period = 0.0
        assert sub._admit_enforced(reader, now - 5_000_000_000, None) is False and sub.dropped_expired == 1
        assert sub._admit_enforced(reader, now, None) is True
    finally:
        sub.close()
    # ordered_by_sending_timestamp: by the sending time the link carries, unless the reader orders itself
    ordered = _Subscription("/contract/order", PointStamped, 100, SubscribeQoSOptions(), TransportHints().tcp(),
                            tag={}, graph="contract")
    try:
        now = time.time_ns()
        admitted = [ordered._admit_enforced(reader, t, None, sent_ns=t) for t in (now, now - 1_000_000, now + 1)]
        if SOURCE_ORDER in reader.enforces:
            assert admitted == [True] * 3 and ordered.dropped_out_of_order == 0, "the core ordered again"
        else:
            assert admitted == [True, False, True] and ordered.dropped_out_of_order == 1, admitted
        assert ordered._admit_enforced(reader, now - 2_000_000, None) is True  # no sending time: arrival order
    finally:
        ordered.close()
    assert (pair.filtering_reader is not None) == (TIME_FILTER in reader.enforces), \
        f"{reader.protocol} declares {set(reader.enforces)}: a reader that says it filters must be shown to"
    if pair.filtering_reader is not None:
        wait_until(pair.matched, 20, "the reader to hear the writer")
        filtered = pair.filtering_reader(30.0)
        try:
            _quiet(reader)
            for i in range(5):
                prepared = pair.writer.prepare(message(i))
                assert prepared is not None
                pair.writer.send(prepared)
            _take(reader, 5)  # the unfiltered reader has them all: so has the filtered one
            got = _take(filtered, 1) + _quiet(filtered)
            assert [m.header.frame_id for m in got] == ["m0"], f"{reader.protocol}'s own time filter let " \
                                                              f"{[m.header.frame_id for m in got]} through"
        finally:
            filtered.close()


def check_a_pushed_reader_feeds_the_core_which_drops_expired_messages(pair: Pair) -> None:
    """End to end through a subscription's delivery thread (pushed readers: TCPROS, MQTT, UDP, fake)."""
    from micros_rt.core.subscription import _Subscription
    from micros_rt.negotiation import TransportHints

    reader = pair.reader
    if not isinstance(reader, PushReader):
        assert reader.protocol == "DDS", f"{reader.protocol}: a reader is either polled (DDS) or pushed"
        return  # DDS samples reach the core through its writer table (test_transports, integration tests)
    wait_until(pair.matched, 20, "the reader to hear the writer")
    _quiet(reader)
    sub = _Subscription("/contract/e2e", PointStamped, 100, SubscribeQoSOptions(ordered_by_sending_timestamp=False),
                        TransportHints().tcp(), tag={}, graph="contract")
    sub.lifespan = 2.0
    got: List[str] = []
    sub.callbacks = ((lambda m: got.append(m.header.frame_id) if m.header.frame_id != PROBE else None, None),)
    sub.pushed = (reader,)
    sub.thread.start()
    try:
        for i, msg in enumerate((message(0), message(1, age=30.0), message(2))):
            if i == 1 and pair.send_stale is not None:
                pair.send_stale(message(1), 30.0)
                continue
            prepared = pair.writer.prepare(msg)
            assert prepared is not None
            pair.writer.send(prepared)

        def delivered() -> bool:
            sub.inbox.wake()
            return len(got) >= 2 and sub.dropped_expired >= 1

        wait_until(delivered, 10, "two fresh messages delivered and the stale one dropped")
        assert got == ["m0", "m2"] and sub.dropped_expired == 1, (got, sub.statistics())
    finally:
        sub.pushed = ()
        sub.close()


def check_close_is_idempotent_and_a_closed_writer_refuses_in_words(pair: Pair) -> None:
    wait_until(pair.matched, 20, "the reader to hear the writer")
    prepared = pair.writer.prepare(message(0))
    assert prepared is not None
    pair.writer.close()
    pair.writer.close()
    pair.reader.close()
    pair.reader.close()
    try:
        pair.writer.send(prepared)
    except MicrosRtError as exc:
        assert "closed" in str(exc), f"the refusal does not say the writer is closed: {exc}"
    else:
        raise AssertionError(f"a closed {pair.writer.protocol} writer sent")


#: in the order they run; the close check last (it closes the pair)
CHECKS: List[Callable[[Pair], None]] = [
    check_interface_is_declared,
    check_prepare_is_none_without_receivers_else_a_payload,
    check_send_delivers_what_was_prepared_equal_and_in_order,
    check_a_bad_value_is_refused_before_anything_is_sent,
    check_malformed_wire_input_raises_a_micros_rt_error_in_words,
    check_what_the_reader_does_not_enforce_the_core_applies,
    check_a_pushed_reader_feeds_the_core_which_drops_expired_messages,
    check_close_is_idempotent_and_a_closed_writer_refuses_in_words,
]
