"""The write-batching flusher (micros_rt.transports.dds.batching): a writer with a latency budget is flushed once
per budget however often it writes, never before its budget, and everything pending leaves at close.

The flush function is a recorder: these test the scheduling, the integration tests the wire."""

from __future__ import annotations

import threading
import time
from typing import List, Tuple

import pytest

from micros_rt.transports.dds.batching import BURST_AGE, BURST_GAP, BURST_IDLE, BURST_TAIL, MAX_BATCH_WINDOW, Flusher, adaptive_write, batch_window


class Recorder:
    def __init__(self) -> None:
        self.calls: List[Tuple[int, float]] = []
        self.event = threading.Event()

    def __call__(self, ref: int) -> int:
        self.calls.append((ref, time.monotonic()))
        self.event.set()
        return 0

    def wait_calls(self, n: int, timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        while len(self.calls) < n and time.monotonic() < deadline:
            time.sleep(0.005)
        assert len(self.calls) >= n, f"{len(self.calls)} flushes, expected {n}: {self.calls}"


def test_many_writes_within_a_budget_make_one_flush_not_before_the_budget() -> None:
    rec = Recorder()
    with Flusher(rec) as f:
        t0 = time.monotonic()
        for _ in range(1000):
            f.pending(7, 0.05)
        rec.wait_calls(1)
        time.sleep(0.1)  # a second flush would come within this if every write scheduled one
        assert [r for r, _ in rec.calls] == [7]
        assert rec.calls[0][1] - t0 >= 0.05


def test_writers_are_flushed_in_order_of_their_deadlines() -> None:
    rec = Recorder()
    with Flusher(rec) as f:
        f.pending(1, 0.30)
        f.pending(2, 0.02)  # due first although scheduled second: the sleeping thread must wake for it
        rec.wait_calls(2)
        assert [r for r, _ in rec.calls] == [2, 1]


def test_a_writer_is_scheduled_again_after_its_flush() -> None:
    rec = Recorder()
    with Flusher(rec) as f:
        f.pending(3, 0.01)
        rec.wait_calls(1)
        f.pending(3, 0.01)
        rec.wait_calls(2)
        assert [r for r, _ in rec.calls] == [3, 3]


def test_close_and_forget_flush_what_is_pending_at_once() -> None:
    rec = Recorder()
    f = Flusher(rec)
    f.pending(4, 60.0)
    f.pending(5, 60.0)
    f.forget(4)  # a writer about to be deleted
    assert [r for r, _ in rec.calls] == [4]
    f.close()
    assert sorted(r for r, _ in rec.calls) == [4, 5]
    f.close()  # harmless twice
    f.pending(6, 0.0)  # after close: nothing scheduled, no thread started
    assert sorted(r for r, _ in rec.calls) == [4, 5]


def test_a_failing_flush_is_logged_and_the_thread_goes_on() -> None:
    rec = Recorder()
    failed: List[int] = []

    def flaky(ref: int) -> int:
        if ref == 8 and not failed:
            failed.append(ref)
            raise OSError("boom")
        return rec(ref)

    with Flusher(flaky) as f:
        f.pending(8, 0.01)
        time.sleep(0.05)
        f.pending(9, 0.01)
        rec.wait_calls(1)
        assert failed == [8] and [r for r, _ in rec.calls] == [9]


def test_batch_window_is_half_the_budget_and_at_most_two_ms() -> None:
    assert batch_window(0.0) == 0.0  # no budget: each sample is sent at once
    assert batch_window(0.001) == 0.0005
    assert batch_window(0.25) == MAX_BATCH_WINDOW == 0.002  # a 30 Hz topic with a generous budget is not delayed


def _writer_batching(writer: object) -> bool:
    """Read the writer-batching QoS back from a live Cyclone writer (the binding does not expose it)."""
    import ctypes

    from cyclonedds.internal import load_cyclonedds
    from cyclonedds.qos import _CQos

    lib = load_cyclonedds()
    lib.dds_qget_writer_batching.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_bool)]
    lib.dds_qget_writer_batching.restype = ctypes.c_bool
    cqos = _CQos.cqos_create()  # type: ignore[no-untyped-call]
    try:
        assert lib.dds_get_qos(writer._ref, cqos) == 0  # type: ignore[attr-defined]
        flag = ctypes.c_bool(False)
        lib.dds_qget_writer_batching(cqos, ctypes.byref(flag))
        return bool(flag.value)
    finally:
        _CQos.cqos_destroy(cqos)  # type: ignore[no-untyped-call]


def test_only_writers_with_a_budget_batch() -> None:
    # in-process Cyclone (loopback config from conftest): the QoS is set on micros_rt's batching
    # writers only; a plain DataWriter in the same process (a user's own cyclonedds code) is untouched
    import os

    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.topic import Topic
    from std_msgs.msg import String

    from micros_rt.transports.dds.batching import batching_writer_class
    from micros_rt.transports.dds.types import dds_type_for

    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    topic = Topic(dp, "rt/micros_rt_test_batched", dds_type_for(String).idl_class)
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=0))
    assert _writer_batching(batching_writer_class()(dp, topic, qos)) is True
    assert _writer_batching(DataWriter(dp, topic, qos)) is False


# --- adaptive_write: batching without a latency budget ------------------------------------------------


class FakeWriter:
    """Cyclone's side of adaptive_write: a clock it controls, the writes (each taking `takes` s), the
    flushes and the flusher registrations, in order."""

    def __init__(self) -> None:
        self.now = 100.0
        self.takes = 2e-6
        self.ret = 0
        self.log: List[str] = []
        self.write = adaptive_write(7, self._write, flush=self._flush, pending=self._pending, clock=lambda: self.now)

    def _write(self, ref: int, data: bytes) -> int:
        assert ref == 7
        self.now += self.takes
        self.log.append(f"write {data.decode()}")
        return self.ret

    def _flush(self, ref: int) -> int:
        self.log.append("flush")
        return 0

    def _pending(self, ref: int, within: float) -> None:
        assert within == BURST_TAIL
        self.log.append("pending")

    def publish(self, data: str, after: float) -> int:
        self.now += after
        return self.write(data.encode())


def test_a_lone_sample_is_sent_at_once() -> None:
    w = FakeWriter()
    w.publish("a", 0.0)
    w.publish("b", 0.01)  # a 100 Hz topic
    w.publish("c", BURST_GAP * 1.5)
    assert w.log == ["write a", "flush", "write b", "flush", "write c", "flush"]


def test_a_burst_shares_a_datagram_sent_by_age_or_by_the_flusher() -> None:
    w = FakeWriter()
    w.publish("a", 1.0)  # lone: sent
    w.publish("b", 5e-6)  # a burst starts: b waits, the flusher is told
    w.publish("c", 5e-6)
    assert w.log == ["write a", "flush", "write b", "pending", "write c", "pending"]
    w.log.clear()
    w.publish("d", BURST_AGE)  # the datagram's oldest (b) is BURST_AGE old: it leaves with d
    w.publish("e", 5e-6)  # a new datagram
    assert w.log == ["write d", "flush", "write e", "pending"]


def test_a_write_that_waited_for_a_slow_reader_stays_in_the_burst() -> None:
    w = FakeWriter()
    w.publish("a", 1.0)
    w.takes = 0.05  # back-pressure: the write blocks 50 ms
    w.publish("b", 5e-6)
    w.takes = 2e-6
    w.publish("c", 5e-6)  # written 5 us after b returned: a burst, though b took 50 ms
    # b's datagram started when b returned; c is within BURST_AGE of it
    assert w.log == ["write a", "flush", "write b", "pending", "write c", "pending"]


def test_one_pause_inside_a_burst_does_not_end_it_two_do() -> None:
    w = FakeWriter()
    w.publish("a", 1.0)  # lone
    w.publish("b", 5e-6)  # burst
    w.takes = BURST_AGE  # c's write itself takes long (back-pressure): not a pause, and b is old when it returns
    w.publish("c", 5e-6)  # sends b and c
    w.takes = 2e-6
    w.log.clear()
    w.publish("d", BURST_GAP * 4)  # a pause (preempted, a GC pass): still the burst, d waits for company
    w.publish("e", 5e-6)
    assert w.log == ["write d", "pending", "write e", "pending"]
    w.log.clear()
    w.publish("f", BURST_AGE)  # a pause that sends d, e, f (age) ...
    w.publish("g", BURST_GAP * 4)  # ... and a second pause in a row: the burst ended, g leaves alone
    assert w.log == ["write f", "flush", "write g", "flush"]


def test_a_pause_longer_than_burst_idle_ends_a_burst_at_once() -> None:
    w = FakeWriter()
    w.publish("a", 1.0)
    w.publish("b", 5e-6)
    w.takes = BURST_AGE
    w.publish("c", 5e-6)  # sends b and c: the datagram is empty, the writer was bursting
    w.takes = 2e-6
    w.log.clear()
    w.publish("d", BURST_IDLE * 1.5)  # a 100 Hz topic's next message after a burst: sent at once
    assert w.log == ["write d", "flush"]


def test_a_failed_write_changes_nothing() -> None:
    w = FakeWriter()
    w.ret = -10  # timed out on back-pressure
    assert w.publish("a", 1.0) == -10
    assert w.log == ["write a"]
    w.ret = 0
    w.publish("b", 1.0)
    assert w.log == ["write a", "write b", "flush"]


def test_burst_tail_outlives_burst_age() -> None:
    # a write after the flusher sent the datagram must not find a sample it believes pending (and so send
    # nothing): the flusher waits BURST_TAIL after a sample joined, the next write sends at BURST_AGE
    assert BURST_TAIL > BURST_AGE > BURST_GAP > 0
    assert BURST_IDLE > BURST_TAIL  # a burst's tail is sent before its writer counts as idle
