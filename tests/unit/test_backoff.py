"""The one retry loop (micros_rt.transports.base.send_with_backoff) and a caller of it outside the writers:
the subscriber's requestTopic to a publisher (transports/tcpros/patches._request_topic)."""

from __future__ import annotations

import math
import socket
import threading
import xmlrpc.server
from typing import Any, Iterator, List

import pytest

from micros_rt.transports.base import BACKOFF_FIRST, BACKOFF_MAX, send_with_backoff


class FakeTime:
    """A clock that only the pauses move, and a record of the pauses and of when each try came."""

    def __init__(self) -> None:
        self.now = 100.0
        self.pauses: List[float] = []
        self.tries: List[float] = []

    def clock(self) -> float:
        return self.now

    def wait(self, seconds: float) -> None:
        self.pauses.append(seconds)
        self.now += seconds

    def failing(self, _: Any) -> bool:
        self.tries.append(self.now)
        return False


def test_backoff_doubles_from_first_to_most_and_gives_up_at_the_first_try_past_the_timeout() -> None:
    t = FakeTime()                              # (binary fractions: the sums are exact)
    assert not send_with_backoff(t.failing, None, 3.75, wait=t.wait, first=0.25, most=1.0, clock=t.clock)
    assert t.pauses == [0.25, 0.5, 1.0, 1.0, 1.0]   # the try right at the timeout is the last
    assert t.tries == [100.0, 100.25, 100.75, 101.75, 102.75, 103.75]
    t = FakeTime()
    assert not send_with_backoff(t.failing, None, 0.015, wait=t.wait, clock=t.clock)   # the defaults
    assert t.pauses[:3] == [BACKOFF_FIRST, 2 * BACKOFF_FIRST, 4 * BACKOFF_FIRST] and max(t.pauses) == BACKOFF_MAX
    assert sum(t.pauses) == pytest.approx(0.015, abs=BACKOFF_MAX)


def test_backoff_times_out_from_the_first_try_not_from_the_call() -> None:
    t = FakeTime()

    def slow_first_try(prepared: Any) -> bool:
        if not t.tries:
            t.now += 1.0                        # a first try that took a second does not use up the timeout
        return t.failing(prepared)

    assert not send_with_backoff(slow_first_try, None, 0.75, wait=t.wait, first=0.25, most=1.0, clock=t.clock)
    assert t.pauses == [0.25, 0.5]


def test_backoff_without_a_timeout_goes_on_at_most_until_closed() -> None:
    t = FakeTime()
    assert not send_with_backoff(t.failing, None, math.inf, lambda: t.now > 160.0, t.wait, first=0.5, most=8.0,
                                 clock=t.clock)
    assert t.pauses == [0.5, 1.0, 2.0, 4.0] + [8.0] * 7 and t.now == pytest.approx(163.5)


def test_backoff_closed_is_asked_before_each_pause_and_a_success_ends_at_once() -> None:
    t = FakeTime()
    assert not send_with_backoff(t.failing, None, 60.0, lambda: True, t.wait, clock=t.clock)
    assert t.pauses == [] and len(t.tries) == 1            # one try, no pause: closed before the first
    t = FakeTime()
    assert send_with_backoff(lambda _: True, None, 0.0, lambda: True, t.wait, clock=t.clock)
    assert t.pauses == []


def test_backoff_succeeds_on_a_later_try_with_the_real_clock() -> None:
    pauses: List[float] = []
    tries: List[int] = []

    def third_time(_: Any) -> bool:
        tries.append(1)
        return len(tries) == 3

    assert send_with_backoff(third_time, None, 10.0, wait=pauses.append)
    assert pauses == [BACKOFF_FIRST, 2 * BACKOFF_FIRST] and BACKOFF_MAX > 2 * BACKOFF_FIRST


def test_backoff_stops_when_closed() -> None:
    closed = threading.Event()
    tries: List[int] = []

    def attempt(_: Any) -> bool:
        tries.append(1)
        if len(tries) == 2:
            closed.set()
        return False

    assert not send_with_backoff(attempt, None, 60.0, closed.is_set, first=0.001)
    assert len(tries) == 2


@pytest.fixture
def publisher() -> Iterator[str]:
    server = xmlrpc.server.SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False, allow_none=False)
    server.register_function(lambda caller, topic, protocols: [1, f"ready on {topic}", ["TCPROS", "127.0.0.1", 1]],
                             "requestTopic")
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def test_request_topic_answers_refuses_at_once_and_names_the_publisher(publisher: str) -> None:
    from micros_rt.transports.tcpros.patches import _request_topic

    assert _request_topic(publisher, "/t", [["TCPROS"]]) == (1, "ready on /t", ["TCPROS", "127.0.0.1", 1])
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        closed_uri = f"http://127.0.0.1:{s.getsockname()[1]}/"  # bound, not listening: refused
        code, msg, result = _request_topic(closed_uri, "/t", [["TCPROS"]])
    assert code == -1 and result is None and msg.startswith(f"publisher {closed_uri} unreachable")
