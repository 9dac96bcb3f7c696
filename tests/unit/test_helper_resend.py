"""The ROS 2 helper's responses that the RMW did not send (rclpy 7 warns, "failed to send response (timeout)", when
rmw_fastrtps gave up waiting 100 ms for the client's response reader): seen per thread, sent again until they go
or their time is up, and then counted and said. rclpy's warning is raised here as rclpy raises it (a
RuntimeWarning through :mod:`warnings`); the real one is in tests/integration/test_services.py."""

from __future__ import annotations

import threading
import time
import warnings
from typing import Any, List

from micros_rt.services import ros2_helper

TIMEOUT = ("failed to send response (timeout): client will not receive response, at /project/src/rmw_response.cpp:153"
           ", at /project/src/rcl/service.c:400")


class FakeService:
    """``send_response`` as rclpy's: warns instead of raising while the client's reader is unknown."""

    def __init__(self, unknown_for: int) -> None:
        self.unknown_for = unknown_for
        self.tries = 0
        self.sent: List[Any] = []

    def send_response(self, response: Any, header: Any) -> None:
        self.tries += 1
        if self.tries <= self.unknown_for:
            warnings.warn(TIMEOUT, RuntimeWarning, stacklevel=1)   # one code location, as in rclpy's service.py
            return
        self.sent.append((response, header))


def wait(cond: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def test_a_response_the_rmw_did_not_send_goes_on_a_later_try() -> None:
    with warnings.catch_warnings():
        ros2_helper._catch_send_timeouts()
        service = FakeService(unknown_for=3)
        assert ros2_helper.send_or_timed_out(service.send_response, "r1", "h1") is False
        resender = ros2_helper.Resender(period=0.01, give_up_after=5.0)
        resender.put("a response of /svc", service.send_response, "r1", "h1")
        wait(lambda: service.sent)
        assert service.sent == [("r1", "h1")] and service.tries == 4
        assert (resender.resent, resender.lost) == (1, 0)
        # every warning of the same line is seen (Python shows one per line by default)
        again = FakeService(unknown_for=1)
        assert ros2_helper.send_or_timed_out(again.send_response, "r2", "h2") is False
        assert ros2_helper.send_or_timed_out(again.send_response, "r2", "h2") is True


def test_a_response_never_taken_is_counted_and_said(capsys: Any) -> None:
    with warnings.catch_warnings():
        ros2_helper._catch_send_timeouts()
        service = FakeService(unknown_for=10 ** 9)
        resender = ros2_helper.Resender(period=0.01, give_up_after=0.2)
        resender.put("a response of /robot/set_mode", service.send_response, "r", "h")
        wait(lambda: resender.lost == 1)
        assert service.sent == [] and service.tries > 2
    err = capsys.readouterr().err
    assert "a response of /robot/set_mode is lost (1 so far)" in err and "not discovered" in err, err


def test_the_flag_is_per_thread_and_other_warnings_still_show() -> None:
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        ros2_helper._catch_send_timeouts()
        results: List[bool] = []
        slow = FakeService(unknown_for=1)
        thread = threading.Thread(target=lambda: results.append(
            ros2_helper.send_or_timed_out(slow.send_response, "x", "y")))
        thread.start()
        thread.join()
        assert ros2_helper.send_or_timed_out(FakeService(unknown_for=0).send_response, "x", "y") is True
        assert results == [False]
        warnings.warn("something else", RuntimeWarning)
    assert [str(w.message) for w in shown] == ["something else"]
