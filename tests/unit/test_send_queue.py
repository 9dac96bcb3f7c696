"""Send queues (micros_rt/core/send_queue.py) on a fake back-pressured writer: the fast path sends inline, a KEEP_LAST
queue never makes publish() wait and sends the newest queue_size in order once there is room (superseded
samples counted, not sent), a lossless queue waits and loses nothing, close gives what waits a bounded
chance; and, with real Cyclone in this process, a writer whose subscriber stopped acknowledging no longer
stalls the interpreter's other threads."""

from __future__ import annotations

import functools
import threading
import time
from typing import Any, List, Tuple

import pytest

import harness

from micros_rt import PublishTimeoutError
from micros_rt.core import send_queue
from micros_rt.core.send_queue import SendQueue
from micros_rt.transports.base import BACKOFF_FIRST, BackPressuredWriter, send_with_backoff


class _Valve:
    """A writer with a valve: closed, it has no room (try_send False), as a throttled DDS writer."""

    protocol = "FAKE"

    def __init__(self) -> None:
        self.open = threading.Event()
        self.open.set()
        self.sent: List[Any] = []
        self.tries = 0
        self.closed = False

    def prepare(self, msg: Any) -> Any:
        return msg

    def may_wait(self, prepared: Any) -> bool:
        return bool(prepared == "large")

    def try_send(self, prepared: Any) -> bool:
        self.tries += 1
        if not self.open.is_set():
            return False
        self.sent.append(prepared)
        return True

    def send(self, prepared: Any) -> None:
        if not send_with_backoff(self.try_send, prepared, 5.0):
            raise PublishTimeoutError("fake: no room for 5 s")

    def close(self) -> None:
        self.closed = True


def test_the_fake_is_a_back_pressured_writer() -> None:
    assert isinstance(_Valve(), BackPressuredWriter)


def test_fast_path_sends_inline_without_a_thread() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=5)
    before = threading.active_count()
    for i in range(100):
        queue.send(i)
    assert valve.sent == list(range(100)) and queue.dropped == 0 and queue.delayed == 0
    assert threading.active_count() == before
    queue.close()
    assert valve.closed


def test_a_large_sample_is_sent_from_the_lanes_thread() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=2)
    caller = threading.get_ident()
    senders: List[int] = []
    original = valve.try_send

    def record(prepared: Any) -> bool:
        senders.append(threading.get_ident())
        return original(prepared)

    valve.try_send = record  # type: ignore[method-assign]
    queue.send("small")
    queue.send("large")
    harness.wait_until(lambda: valve.sent == ["small", "large"], 10)
    assert senders[0] == caller and senders[1] != caller
    queue.close()


def test_keep_last_lane_never_waits_and_sends_the_newest_in_order() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=3)
    queue.send("a")
    valve.open.clear()
    t0 = time.monotonic()
    for i in range(10):
        queue.send(i)                                   # no room: queued, never waits
    assert time.monotonic() - t0 < 1.0
    harness.wait_until(lambda: valve.tries > 3, 10, message="the queue's thread retries")
    valve.open.set()
    harness.wait_until(lambda: len(valve.sent) == 4, 10, message="the newest three sent")
    assert valve.sent == ["a", 7, 8, 9]
    assert queue.dropped == 7 and queue.delayed == 10
    queue.send("after")                                # the queue is empty again: in order, after the rest
    harness.wait_until(lambda: valve.sent[-1] == "after", 10)
    assert valve.sent == ["a", 7, 8, 9, "after"]
    queue.close()


def test_keep_last_order_holds_while_the_thread_drains() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=1000)
    valve.open.clear()
    for i in range(200):
        queue.send(i)
    valve.open.set()
    for i in range(200, 2000):
        queue.send(i)                                   # behind the queued ones, never before them
    harness.wait_until(lambda: len(valve.sent) + queue.dropped == 2000, 20, message="all 2000 sent or dropped")
    # a producer faster than the link loses the oldest (counted), never the order
    assert valve.sent == sorted(valve.sent) and len(set(valve.sent)) == len(valve.sent)
    assert valve.sent[-1] == 1999
    queue.close()


def test_the_lanes_thread_retries_in_the_one_loop_whose_pauses_span_superseded_samples(
        monkeypatch: pytest.MonkeyPatch) -> None:
    valve = _Valve()
    valve.open.clear()
    queue = SendQueue(valve, topic="/t", depth=1)
    pauses: List[float] = []

    def wait(seconds: float) -> None:       # on the queue's thread, between two tries
        pauses.append(seconds)
        if len(pauses) == 3:
            queue.send("b")                  # supersedes "a", which the thread is trying
        elif len(pauses) in (6, 8):
            valve.open.set()

    monkeypatch.setattr(send_queue, "send_with_backoff", functools.partial(send_with_backoff, wait=wait))
    queue.send("a")
    harness.wait_until(lambda: valve.sent == ["b"], 5.0, message="b sent")
    # one loop for "a" and then "b": the pauses go on doubling, they do not start again at "b"
    assert pauses == [BACKOFF_FIRST * 2 ** i for i in range(6)] and queue.dropped == 1
    valve.open.clear()
    queue.send("c")                          # no room: to the queue's thread, whose pauses start again
    harness.wait_until(lambda: valve.sent == ["b", "c"], 5.0, message="c sent")
    assert pauses[6:] == [BACKOFF_FIRST, 2 * BACKOFF_FIRST]
    queue.close()


def test_lossless_lane_waits_for_room_and_loses_nothing() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=None)
    valve.open.clear()
    threading.Timer(0.3, valve.open.set).start()
    t0 = time.monotonic()
    queue.send("x")
    assert time.monotonic() - t0 >= 0.25 and valve.sent == ["x"] and queue.dropped == 0
    queue.close()


def test_close_gives_waiting_samples_a_bounded_chance_then_counts_them() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=5)
    valve.open.clear()
    for i in range(5):
        queue.send(i)
    t0 = time.monotonic()
    queue.close()
    assert time.monotonic() - t0 < 5.0
    assert valve.sent == [] and queue.dropped == 5 and valve.closed


def test_a_waiting_dds_write_leaves_other_threads_running() -> None:
    """A reliable writer whose reader stopped acknowledging (a reader without a thread to answer: its
    process is stopped) used to wait inside Cyclone holding the GIL: a counting thread got 0.3 % of its
    speed for 1.5 s. Now the wait is in Python."""
    import os
    import signal
    import subprocess
    import sys

    from std_msgs.msg import String

    from micros_rt.transports.dds.backend import DDSBackend
    from micros_rt.transports.dds.participant import get_participant
    from micros_rt.qos import AdvertiseQoSOptions
    from micros_rt.transports.base import EndpointSpec

    topic = f"/micros_rt_lane_gil_{os.getpid()}"
    reader_code = (
        "import sys, time\n"
        "from std_msgs.msg import String\n"
        "from micros_rt.transports.dds.backend import DDSBackend\n"
        "from micros_rt.transports.dds.participant import get_participant\n"
        "from micros_rt.transports.base import EndpointSpec\n"
        f"spec = EndpointSpec({topic!r}, String, None, False, {{'graph': 'g', 'node': '/r'}})\n"
        "r = DDSBackend(get_participant(), 'r').open_reader(spec, None, lambda: None, lambda p: None)\n"
        "print('ready', flush=True)\n"
        "while True:\n"
        "    r.take(256); time.sleep(0.001)\n")
    proc = subprocess.Popen([sys.executable, "-c", reader_code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        participant = get_participant()
        assert participant is not None
        spec = EndpointSpec(topic, String, None, False, {"graph": "g", "node": "/w"})
        writer = DDSBackend(participant, "w").open_writer(spec, AdvertiseQoSOptions())
        harness.wait_until(lambda: bool(writer.matched_peers()), 20, message="the reader matched")
        os.kill(proc.pid, signal.SIGSTOP)
        count = [0]
        stop = threading.Event()

        def spin() -> None:
            while not stop.is_set():
                count[0] += 1

        data = writer.prepare(String(data="x" * 200_000))
        assert data is not None and writer.try_send(data)
        refused = 0
        spinner = threading.Thread(target=spin, daemon=True)
        spinner.start()
        t0 = time.monotonic()
        for _ in range(50):                             # until the window is full
            if not writer.try_send(data):
                refused += 1
                break
        # try for a while the way a queue does; the spinner must get a fair share meanwhile
        while time.monotonic() - t0 < 0.5:
            writer.try_send(data)
            time.sleep(0.001)
        elapsed = time.monotonic() - t0
        stop.set()
        spinner.join()
        rate_during = count[0] / elapsed
        count[0] = 0
        stop.clear()
        spinner = threading.Thread(target=spin, daemon=True)
        t1 = time.monotonic()
        spinner.start()
        time.sleep(0.3)
        stop.set()
        spinner.join()
        rate_alone = count[0] / (time.monotonic() - t1)
        assert refused == 1, "the stopped reader's window never filled"
        assert rate_during > 0.2 * rate_alone, (rate_during, rate_alone)
        writer.close()
    finally:
        os.kill(proc.pid, signal.SIGCONT)
        proc.kill()
        proc.wait(10)


@pytest.mark.parametrize("depth", [1, 2])
def test_superseded_while_in_flight_is_counted_once(depth: int) -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/t", depth=depth)
    valve.open.clear()
    queue.send("old")
    harness.wait_until(lambda: valve.tries >= 2, 10, message="the thread is trying 'old'")
    for i in range(depth):
        queue.send(i)                                  # 'old' falls out of the newest `depth`
    valve.open.set()
    harness.wait_until(lambda: len(valve.sent) >= depth and not queue._active, 10, message="the queue drained")
    # 'old' either left just before it was superseded (then it is not a drop) or was given up (a drop)
    assert queue.dropped == (0 if "old" in valve.sent else 1)
    assert valve.sent[-depth:] == list(range(depth))
    queue.close()


def test_a_large_write_that_waits_marks_the_socket_congested_then_small_writes_release_the_gil(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The heuristic behind HIGH-beside-LOW on one socket: a large write that waited on the network makes
    every write of that participant release the GIL (and KEEP_LAST send queues send from their threads) until it
    has been quiet; another participant's socket (another transport priority) is not congested by it."""
    from micros_rt.transports.dds import congestion

    calls: List[Tuple[str, int]] = []

    def c_write(ref: int, container: Any) -> int:      # the C dds_write, waiting for socket room
        calls.append(("released", ref))
        time.sleep(0.02)
        return 0

    def binding_write(ref: int, data: bytes) -> int:   # cyclonedds-python's own call
        calls.append(("binding", ref))
        return 0

    monkeypatch.setattr(congestion, "_c_dds_write", c_write)
    socket, other = congestion.SocketCongestion(), congestion.SocketCongestion()
    write, other_write = socket.sample_write(binding_write), other.sample_write(binding_write)
    small, large = bytes(64), bytearray(congestion.RELEASED_WRITE_MIN)
    assert write(1, small) == 0
    assert not socket.active()
    assert write(2, large) == 0
    assert socket.active() and socket.network_bound(2) and not socket.network_bound(1)
    write(3, small)
    other_write(5, small)                              # another participant's writer: its own socket
    assert not other.active()
    harness.wait_until(lambda: not socket.active(), 10, message="quiet again")
    write(4, small)
    assert calls == [("binding", 1), ("released", 2), ("released", 3), ("binding", 5), ("binding", 4)]


def test_samples_older_than_max_age_are_not_sent_and_are_counted() -> None:
    valve = _Valve()
    queue = SendQueue(valve, topic="/camera", depth=10, max_age=0.2)
    valve.open.clear()                     # the link has no room
    for i in range(3):
        queue.send(i)                       # they wait in the queue
    harness.wait_until(lambda: valve.tries >= 3, 10, interval=0.01, message="the queue's thread tried")
    time.sleep(0.3)                        # (the age being tested) they are now older than max_age
    queue.send(3)                           # a fresh one
    valve.open.set()
    harness.wait_until(lambda: 3 in valve.sent, 10, interval=0.01, message="the fresh sample sent")
    assert valve.sent == [3], valve.sent   # the stale three never left
    assert queue.expired == 3 and queue.dropped == 3
    queue.close()


def test_max_age_is_the_lifespan_and_for_best_effort_also_the_budget() -> None:
    import math

    from micros_rt import AdvertiseQoSOptions
    from micros_rt.core.send_queue import max_age_for

    assert max_age_for(AdvertiseQoSOptions()) == math.inf
    assert max_age_for(AdvertiseQoSOptions(msg_valid_period=0.5, latency_budget=0.1)) == 0.5  # reliable: retried
    assert max_age_for(AdvertiseQoSOptions(msg_valid_period=0.5, latency_budget=0.1,
                                           using_best_effort_protocol=True)) == 0.1
    assert max_age_for(AdvertiseQoSOptions(using_best_effort_protocol=True)) == math.inf  # no budget: no limit


def test_sender_for_is_the_one_rule_of_publications_and_the_relay() -> None:
    # the relay's exports built their queue without the rule's lifespan (issue 36: relay.py against
    # publication.py); both now go through sender_for
    import inspect

    from micros_rt.bridges.relay import relay
    from micros_rt.core import publication
    from micros_rt.core.send_queue import sender_for
    from micros_rt.qos import AdvertiseQoSOptions

    class Plain:
        protocol = "X"

    plain = Plain()
    assert sender_for(plain, topic="/t", queue_size=5, options=None) is plain  # type: ignore[arg-type,comparison-overlap]
    for module in (relay, publication):
        assert "sender_for(" in inspect.getsource(module) and "SendQueue(" not in inspect.getsource(module)
    options = AdvertiseQoSOptions(msg_valid_period=0.25)
    queue = sender_for(_Valve(), topic="/t", queue_size=0, options=options)
    try:
        assert isinstance(queue, SendQueue) and queue.max_age == 0.25 and queue.depth is None  # lossless: waits, keeps all
    finally:
        queue.close()
