"""The one retry loop (micros_rt.transports.base.send_with_backoff) and a caller of it outside the writers:
the subscriber's requestTopic to a publisher (transports/tcpros/patches._request_topic)."""

from __future__ import annotations

import socket
import threading
import xmlrpc.server
from typing import Any, Iterator, List

import pytest

from micros_rt.transports.base import BACKOFF_FIRST, BACKOFF_MAX, send_with_backoff


def test_backoff_doubles_from_first_to_most_and_gives_up_at_the_timeout() -> None:
    pauses: List[float] = []
    # wait records instead of sleeping: the loop ends on the clock
    assert not send_with_backoff(lambda _: False, None, 0.05, wait=pauses.append, first=0.001, most=0.004)
    assert pauses[:4] == [0.001, 0.002, 0.004, 0.004]
    pauses.clear()
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
