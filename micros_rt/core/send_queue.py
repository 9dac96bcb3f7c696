"""Per-topic send queues: between ``publish()`` and a transport writer that can say "no room now".

They keep topics apart, not priorities: transport priority is carried by the transports (DSCP marks, DDS
participants per priority, link pacing) and by the receiving side's delivery threads.

A transport priority is a promise about a topic, so back-pressure on one topic must never hold another.
A send queue sits in front of each :class:`~micros_rt.transports.base.BackPressuredWriter` of a publication
(DDS today; any transport that implements ``try_send`` gets one) and keeps ``publish()`` the way
rospy's is:

- ``queue_size=N`` (KEEP_LAST): ``publish()`` never waits. When the writer has no room (a reliable
  subscriber behind a slow link has not acknowledged enough), or the sample is large enough that sending
  it waits on the network (a camera frame: hundreds of datagrams into a socket buffer that a slow link
  drains), the send queue keeps the newest N samples and a thread of its own sends them in order; a sample
  superseded before it left is not sent, and is counted in ``Publisher.statistics().dropped`` (rospy's
  queued publisher drops the same way, per connection).
- ``queue_size=None`` (lossless): ``publish()`` waits until the writer takes the sample, bounded, and
  waits in Python (:func:`~micros_rt.transports.base.send_with_backoff`), so the process's other threads
  and topics go on meanwhile.

The fast path (no back-pressure, nothing queued) is one ``try_send`` on the caller's thread: no thread
hop, no lock.

Stale samples are not sent: a sample that waited in the send queue longer than ``max_age`` (the topic's lifespan,
``msg_valid_period``, and for a best-effort topic its ``latency_budget`` too, see :func:`max_age_for`) is
dropped whole before it leaves, counted in ``expired`` (and in ``dropped``). A camera frame that could not
leave while a radio link was full goes when it is still worth something, or not at all.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from typing import Any, Deque, Optional, Tuple

from ..log import nonblocking_logger
from ..qos import is_lossless
from ..transports.base import BackPressuredWriter, TransportWriter, send_with_backoff

__all__ = ["SendQueue", "QUEUE_IDLE_EXIT", "QUEUE_CLOSE_FLUSH", "max_age_for"]

_log = nonblocking_logger("rosout.micros_rt")

#: A send queue's thread ends after this many seconds with nothing to send (it starts again when needed).
QUEUE_IDLE_EXIT = 2.0
#: At close, what a send queue still holds gets this many seconds to leave; the rest is dropped and counted.
QUEUE_CLOSE_FLUSH = 1.0


def max_age_for(options: Any) -> float:
    """How long a sample of a publication with ``options`` (:class:`~micros_rt.qos.AdvertiseQoSOptions`) may
    wait in its send queue: its lifespan, and for best effort also its latency budget (0: no budget, no limit)."""
    if options is None:
        return math.inf
    age = float(options.msg_valid_period)
    budget = float(options.latency_budget)
    if options.using_best_effort_protocol and budget > 0:
        age = min(age, budget)
    return age


def sender_for(writer: TransportWriter, *, topic: str, queue_size: Optional[int], options: Any) -> TransportWriter:
    """What a publication (or a program driving a writer itself, the relay) sends through: a back-pressured
    writer behind a send queue that keeps the newest ``queue_size`` (lossless, ``None``/0: ``publish()`` waits
    instead) and drops samples older than ``options``' lifespan (:func:`max_age_for`); any other writer as is."""
    if not isinstance(writer, BackPressuredWriter):
        return writer
    return SendQueue(writer, topic=topic, depth=None if is_lossless(queue_size) else queue_size,
                max_age=max_age_for(options))


class SendQueue:
    """One publication's send queue in front of one back-pressured writer (see the module's text)."""

    def __init__(self, writer: BackPressuredWriter, *, topic: str, depth: Optional[int],
                 max_age: float = math.inf) -> None:
        self.writer = writer
        self.protocol = writer.protocol
        self.topic = topic
        self.depth = depth                      # None: lossless, publish() waits instead of queueing
        self.max_age = max_age                  # seconds a sample may wait here before it is not worth sending
        self.dropped = 0                        # superseded before they left (KEEP_LAST), or expired
        self.expired = 0                        # waited longer than max_age: dropped, not sent
        self.delayed = 0                        # KEEP_LAST samples handed to the send queue's thread
        self._queue: Deque[Tuple[Any, float]] = collections.deque()   # (prepared sample, when it came)
        self._active = False                    # samples wait here: publish() must queue behind them
        self._inflight: Any = None              # the (sample, when) the send queue's thread is trying to send
        self._superseded = False                # ... and newer ones pushed it out of the newest `depth`
        self._cond = threading.Condition()
        self._thread: Optional[threading.Thread] = None
        self._closed = False
        self._close_deadline = float("inf")
        self._burst = 0                         # dropped since the last report
        self._sent_at = time.monotonic()        # when the send queue's thread last sent (it ends when idle long)

    def prepare(self, msg: Any) -> Any:
        return self.writer.prepare(msg)

    def send(self, prepared: Any) -> None:
        """From ``publish()`` (under the publication's lock: calls come one at a time)."""
        if self.depth is None:
            # lossless: nothing is ever queued here, so order holds; the writer waits (bounded) in Python
            self.writer.send(prepared)
            return
        if not self._active and not self.writer.may_wait(prepared) and self.writer.try_send(prepared):
            return
        # no room, or a large sample whose sending waits on the network: the send queue's thread sends it
        self.delayed += 1
        with self._cond:
            self._active = True
            self._queue.append((prepared, time.monotonic()))
            pending = len(self._queue) + (1 if self._inflight is not None and not self._superseded else 0)
            while pending > self.depth:
                if self._inflight is not None and not self._superseded:
                    self._superseded = True     # the oldest is the one the thread is trying: give it up
                else:
                    self._queue.popleft()
                pending -= 1
                self.dropped += 1
                self._burst += 1
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=f"micros_rt send queue {self.topic}", daemon=True)
                self._thread.start()
            else:
                self._cond.notify()

    def _stale(self, item: Tuple[Any, float]) -> bool:
        """True (and counted) when ``item`` waited longer than ``max_age`` (under the lock)."""
        if time.monotonic() - item[1] <= self.max_age:
            return False
        self.expired += 1
        self.dropped += 1
        self._burst += 1
        return True

    def _head(self) -> Any:
        """The (sample, when) to try now, passing over the superseded and the stale; None when the send queue holds
        nothing (under the lock)."""
        if self._inflight is not None and not self._superseded and not self._stale(self._inflight):
            return self._inflight
        self._inflight, self._superseded = None, False
        while self._queue:
            item = self._queue.popleft()
            if not self._stale(item):
                self._inflight = item
                return item
        self._active = False
        return None

    def _wait_for_work(self) -> bool:
        """True when the send queue holds a sample to send; False (the thread ends) once it is closed or has had
        nothing to send for :data:`QUEUE_IDLE_EXIT` seconds."""
        with self._cond:
            while self._head() is None:
                if self._closed or time.monotonic() - self._sent_at > QUEUE_IDLE_EXIT:
                    self._thread = None
                    return False
                self._cond.wait(QUEUE_IDLE_EXIT / 4)
            return True

    def _try_head(self, _: Any) -> bool:
        """One try at the oldest sample still worth sending: True when it left or nothing is left to send. One
        retry loop spans the samples superseded or out of date while the link had no room, so its pauses go
        on growing as they did for the first."""
        with self._cond:
            item = self._head()
        if item is None:
            return True
        try:
            sent = self.writer.try_send(item[0])
        except Exception:
            _log.exception("micros_rt: topic %s: sending a queued %s sample failed; dropped", self.topic,
                           self.protocol)
            sent = True
        if not sent:
            return False
        with self._cond:
            if self._inflight is item:
                if self._superseded:        # it left after all: not a drop
                    self.dropped -= 1
                    self._burst -= 1
                self._inflight, self._superseded = None, False
            burst, self._burst = self._burst, 0
        if burst > 0:
            _log.warning("micros_rt: topic %s: %d %s samples were superseded%s before the link had room for "
                         "them and were not sent (queue_size=%d keeps the newest, as ROS does; %d in all%s)",
                         self.topic, burst, self.protocol,
                         "" if math.isinf(self.max_age) else f" or older than {self.max_age:g} s",
                         self.depth or 0, self.dropped,
                         f", {self.expired} out of date" if self.expired else "")
        self._sent_at = time.monotonic()
        return True

    def _flush_over(self) -> bool:
        """True once the send queue is closed and :data:`QUEUE_CLOSE_FLUSH` has passed: the retries stop."""
        return self._closed and time.monotonic() > self._close_deadline

    def _run(self) -> None:
        self._sent_at = time.monotonic()
        while self._wait_for_work():
            if send_with_backoff(self._try_head, None, math.inf, self._flush_over):
                continue
            with self._cond:
                lost = len(self._queue) + (1 if self._inflight is not None and not self._superseded else 0)
                self._queue.clear()
                self._inflight, self._superseded, self._active = None, False, False
                self.dropped += lost
                self._thread = None
            if lost:
                _log.warning("micros_rt: topic %s: %d %s samples were still waiting for room when the "
                             "publisher closed; dropped", self.topic, lost, self.protocol)
            return

    def close(self) -> None:
        """Give what the send queue holds :data:`QUEUE_CLOSE_FLUSH` seconds to leave, then close the writer."""
        with self._cond:
            self._close_deadline = time.monotonic() + QUEUE_CLOSE_FLUSH
            self._closed = True
            thread = self._thread
            self._cond.notify()
        if thread is not None and thread is not threading.current_thread():
            thread.join(QUEUE_CLOSE_FLUSH + 1.0)
        self.writer.close()
