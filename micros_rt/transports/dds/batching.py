"""Write batching: several samples share one datagram, sent within the writer's latency budget.

Every sendmsg on loopback costs ~5 µs here (measured with plain sockets: UDP 5.2 µs, TCP 4.8 µs per
send); a 64 B sample is ~2 µs of everything else. One datagram per sample therefore caps a publisher
at the speed of the kernel, the same as TCPROS, and a reader at one wake-up per sample. Cyclone can
pack samples into the writer's pending datagram (the writer-batching QoS, ``dds_qset_writer_batching``),
but then it sends a datagram only when it is full or flushed: something has to flush.

micros_rt decides per writer:

* ``latency_budget == 0`` (the default): batching as TCP's autocorking does it (:func:`adaptive_write`).
  A write that follows the writer's previous one by more than :data:`BURST_GAP` is sent at once, so a
  lone message (a 100 Hz topic, a ping-pong) leaves as without batching, unless it follows a burst by
  less than :data:`BURST_IDLE` (one pause inside a burst does not end it). Writes closer together are a
  burst: they share a datagram, which leaves at the first write :data:`BURST_AGE` after its oldest
  sample, when it is full, or, once the burst ended, by the flusher within :data:`BURST_TAIL`. A
  stream above ~20 kHz then pays at most BURST_AGE (0.5 ms) of latency and sends one datagram where it
  sent a hundred. Benchmark, 64 B one way: 88 k msg/s -> 182-244 k; fan-out to 4 subscribers 69 k ->
  306-397 k with 1.3-1.7 us of publisher CPU per message instead of 8 (BURST_AGE 0.1 ms gave far less:
  subscribers then spend their time on datagrams).
* ``latency_budget > 0``: the writer is created with writer batching (:func:`batching_writer_class`);
  each sample waits in the pending datagram and let the process's one
  :class:`Flusher` thread send it within :func:`batch_window` of the first unsent write: half the
  budget (the other half is for the wire and the subscriber), at most 2 ms. Batching gains nothing
  from a longer wait: at 150 k msg/s, 2 ms already fill a datagram with 300 64 B samples, while a
  30 Hz topic would only see its messages late. A burst goes out in full 64 KB datagrams; a lone
  sample leaves after the window. That is what DDS's
  LatencyBudget means ("a hint to batch"), done here instead of Cyclone's own latency-budget mode,
  which hands every sample to its send thread (measured: 63 k msg/s, 13.8 µs of CPU per 64 B sample,
  against 98 k without it and 260 k batched and flushed).

A batching writer that blocks on a full history (back-pressure) still gets its samples out: the
lossless 100,000-message test with a budget passes (tests/integration/test_lossless.py).
"""

from __future__ import annotations

import ctypes
import heapq
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from ...cyclone import import_cyclonedds
from ...log import nonblocking_logger

__all__ = ["BURST_AGE", "BURST_GAP", "BURST_IDLE", "BURST_TAIL", "MAX_BATCH_WINDOW", "Flusher", "adaptive_write",
           "c_function",
           "batch_window", "batching_writer_class", "budget_write", "close_flusher", "flush_writer", "flusher"]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: The longest a sample waits in its writer's datagram (seconds), whatever the budget.
MAX_BATCH_WINDOW = 0.002
#: Without a latency budget: a write within this long (s) of the writer's previous one is part of a burst.
BURST_GAP = 50e-6
#: A pause this long (s) ends a burst; a shorter one ends it only when the next write pauses too.
BURST_IDLE = 0.002
#: A burst's datagram leaves at the first write this long (s) after its oldest sample ...
BURST_AGE = 500e-6
#: ... or, when no such write comes, by the flusher this long (s) after a sample joined it. Longer than
#: BURST_AGE, so a write after the flusher sent the datagram never finds a sample it believes pending.
BURST_TAIL = 0.001

_flush_fn: Optional[Callable[[int], int]] = None


def batch_window(latency_budget: float) -> float:
    """How long a writer with ``latency_budget`` (s) lets samples gather: 0 means send each at once.

    >>> batch_window(0.0), batch_window(0.001), batch_window(0.25)
    (0.0, 0.0005, 0.002)
    """
    return min(latency_budget * 0.5, MAX_BATCH_WINDOW) if latency_budget > 0 else 0.0


def c_function(name: str, argtypes: List[Any], restype: Any) -> Any:
    """Cyclone's C function ``name`` through ctypes (which releases the GIL during the call)."""
    import_cyclonedds()
    from cyclonedds.internal import load_cyclonedds

    fn = getattr(load_cyclonedds(), name)
    fn.argtypes = argtypes
    fn.restype = restype
    return fn


def flush_writer(ref: int) -> int:
    """Send what writer ``ref`` has pending now (``dds_write_flush``); Cyclone's return code."""
    global _flush_fn
    fn = _flush_fn
    if fn is None:
        fn = _flush_fn = c_function("dds_write_flush", [ctypes.c_int32], ctypes.c_int32)
    return int(fn(ref))


def budget_write(ref: int, write: Callable[[int, bytes], int], window: float) -> Callable[[bytes], int]:
    """``write_serialized`` for batching writer ``ref`` with a latency budget: every sample waits in the
    datagram, which leaves when full or from the flusher within ``window`` (:func:`batch_window`)."""
    pending = flusher().pending

    def write_serialized(data: bytes) -> int:
        ret = write(ref, data)
        if ret >= 0:
            pending(ref, window)  # sent with the next full datagram, or by the flusher within window
        return ret
    return write_serialized


def adaptive_write(ref: int, write: Callable[[int, bytes], int], *, flush: Optional[Callable[[int], int]] = None,
                   pending: Optional[Callable[[int, float], None]] = None,
                   clock: Callable[[], float] = time.monotonic) -> Callable[[bytes], int]:
    """``write_serialized`` for batching writer ``ref`` without a latency budget: a lone sample is sent at
    once, a burst shares datagrams (see the module's text). Calls come one at a time per writer (the
    publication's lock); the flusher may flush concurrently, which Cyclone allows."""
    flush = flush or flush_writer
    pending = pending or flusher().pending
    returned = -1.0  # when the previous write returned
    oldest = 0.0  # when the oldest sample in the datagram was written (0.0: the datagram is empty)
    was_spaced = True  # the previous write, too, came after an idle gap

    def write_serialized(data: bytes) -> int:
        nonlocal returned, oldest, was_spaced
        start = clock()
        ret = write(ref, data)
        if ret < 0:
            return ret
        now = clock()
        # idle since the previous write returned, not how long this one took: a write that waited for a slow
        # reader (back-pressure) is still part of the burst, and a burst must stay batched then, or the reader
        # gets one datagram per sample and falls further behind
        idle = start - returned
        spaced = idle > BURST_GAP
        if oldest == 0.0:
            # one pause inside a burst (the thread preempted, a garbage collection) does not end it: only a
            # second gap in a row, or one longer than BURST_IDLE, makes a lone sample (measured, fan-out to 4
            # subscribers on 2 cores: 187-230 k msg/s when each pause sent a sample alone, 313-397 k without)
            if spaced and (was_spaced or idle > BURST_IDLE):
                flush(ref)  # a lone sample
            else:
                oldest = now
                pending(ref, BURST_TAIL)
        elif now - oldest >= BURST_AGE:
            flush(ref)
            oldest = 0.0
        else:
            pending(ref, BURST_TAIL)  # one dict lookup when the flusher already has this writer
        returned = now
        was_spaced = spaced
        return ret
    return write_serialized


_writer_class: Any = None


def batching_writer_class() -> Any:
    """A ``cyclonedds.pub.DataWriter`` whose writers batch their samples (writer-batching QoS, which
    the Python binding does not expose: set on the C QoS right before ``dds_create_writer``). Only
    micros_rt's own topic writers batch; every other writer in the process sends as Cyclone always does."""
    global _writer_class
    if _writer_class is None:
        import_cyclonedds()
        from cyclonedds.pub import DataWriter

        qset = c_function("dds_qset_writer_batching", [ctypes.c_void_p, ctypes.c_bool], None)

        class BatchingDataWriter(DataWriter):  # type: ignore[type-arg]
            def _create_writer(self, publisher: Any, topic: Any, qos: Any, listener: Any) -> Any:
                if qos is not None:
                    qset(qos, True)
                return DataWriter._create_writer(self, publisher, topic, qos, listener)

        _writer_class = BatchingDataWriter
    return _writer_class


class Flusher:
    """Sends batched samples within their writers' latency budgets: one thread per process, asleep
    while nothing is pending.

    ``pending(ref, budget)`` is called after every write of a batching writer. The fast path (the
    writer is already due) is one dict lookup without a lock, so a burst costs next to nothing; the
    write always happens before that check, so a flush that races with it still sends the sample.
    """

    def __init__(self, flush: Callable[[int], int] = flush_writer) -> None:
        self._flush = flush
        self._due: Dict[int, float] = {}
        self._heap: List[Tuple[float, int]] = []
        self._cond = threading.Condition()
        self._thread: Optional[threading.Thread] = None
        self._closed = False
        self.flushes = 0

    def pending(self, ref: int, budget: float) -> None:
        """Writer ``ref`` wrote a sample that waits in its datagram; send it within ``budget`` s."""
        if ref in self._due:
            return
        due = time.monotonic() + budget
        with self._cond:
            if ref in self._due or self._closed:
                return
            self._due[ref] = due
            heapq.heappush(self._heap, (due, ref))
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="micros_rt write batching", daemon=True)
                self._thread.start()
            elif self._heap[0][1] == ref:
                self._cond.notify()

    def forget(self, ref: int) -> None:
        """Flush ``ref`` now and stop tracking it (before the writer is deleted)."""
        with self._cond:
            self._due.pop(ref, None)
        self._flush(ref)

    def _run(self) -> None:
        while True:
            ready: List[int] = []
            with self._cond:
                while not self._closed:
                    now = time.monotonic()
                    while self._heap and self._heap[0][0] <= now:
                        _, ref = heapq.heappop(self._heap)
                        if self._due.pop(ref, None) is not None:
                            ready.append(ref)
                    if ready:
                        break
                    self._cond.wait(self._heap[0][0] - now if self._heap else None)
                if self._closed and not ready:
                    return
            for ref in ready:  # outside the lock: writers keep writing meanwhile
                try:
                    self._flush(ref)
                    self.flushes += 1
                except Exception:
                    _log.exception("micros_rt: flushing batched DDS samples failed (continuing)")

    def close(self) -> None:
        """Flush everything pending and stop the thread; harmless twice."""
        with self._cond:
            self._closed = True
            refs = list(self._due)
            self._due.clear()
            self._heap.clear()
            self._cond.notify_all()
        for ref in refs:
            try:
                self._flush(ref)
            except Exception:
                _log.exception("micros_rt: flushing batched DDS samples at close failed")
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    def __enter__(self) -> "Flusher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_flusher: Optional[Flusher] = None
_flusher_lock = threading.Lock()


def flusher() -> Flusher:
    """The process's flusher (created on first use)."""
    global _flusher
    with _flusher_lock:
        if _flusher is None or _flusher._closed:
            _flusher = Flusher()
        return _flusher


def close_flusher() -> None:
    """Flush what is pending and stop the process's flusher (at shutdown); harmless when none runs."""
    global _flusher
    with _flusher_lock:
        f, _flusher = _flusher, None
    if f is not None:
        f.close()
