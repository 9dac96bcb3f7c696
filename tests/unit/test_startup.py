"""Start-up pieces of a node (no master, no DDS): rospy's registration poll made prompt, and restored."""

from __future__ import annotations

import time
from typing import List

import pytest
import rospy.impl.init

from micros_rt.transports.tcpros import patches as compat


def test_registration_poll_starts_fine_and_backs_off_to_rospys_step(monkeypatch: pytest.MonkeyPatch) -> None:
    slept: List[float] = []
    monkeypatch.setattr(time, "sleep", slept.append)
    with compat.prompt_registration_poll():
        polled = rospy.impl.init.time
        for _ in range(9):
            polled.sleep(0.1)  # what start_node does while the master has not answered
        polled.sleep(0.00001)  # its XML-RPC start poll: passed through as asked
    assert slept[:6] == pytest.approx([0.002, 0.004, 0.008, 0.016, 0.032, 0.064])
    assert slept[6:9] == pytest.approx([0.1, 0.1, 0.1])  # a master that is down: rospy's own pace, no faster
    assert slept[9] == pytest.approx(0.00001)
    assert polled.monotonic is time.monotonic  # everything else is the real module's


def test_registration_poll_is_rospys_again_after_the_block_even_on_error() -> None:
    original = rospy.impl.init.time
    with pytest.raises(RuntimeError):
        with compat.prompt_registration_poll():
            assert rospy.impl.init.time is not original
            raise RuntimeError("init_node failed")
    assert rospy.impl.init.time is original


def test_the_first_topic_waits_for_the_dds_import_started_by_init_node(monkeypatch: pytest.MonkeyPatch) -> None:
    # a subscribe right after init_node once imported cyclonedds while the early-import thread was still at
    # it, and met a half-initialised module (ImportError); the first topic must wait for that thread
    import threading

    import micros_rt.node  # noqa: F401  (the node makes a topic wait for the DDS import)
    from micros_rt.core import runtime as _runtime
    from micros_rt.transports.dds import process as _process

    importing = threading.Thread(target=time.sleep, args=(0.3,), name="slow import stand-in", daemon=True)
    monkeypatch.setattr(_runtime._node, "initialized", True)
    monkeypatch.setattr(_process._state, "start", importing)
    importing.start()
    _runtime._require_node()
    assert not importing.is_alive()
    assert _process._state.start is None  # later topics do not join again


def test_dds_backend_waits_for_the_dds_import_started_by_init_node(monkeypatch: pytest.MonkeyPatch) -> None:
    # the relay asks for the back end before any topic: it imported micros_rt's DDS modules beside the
    # early-import thread and met a half-initialised cyclonedds module (1 of 24 relay starts in relay_hop)
    import threading

    from micros_rt import node as _runtime
    from micros_rt.transports.dds import process as _process

    importing = threading.Thread(target=time.sleep, args=(0.3,), name="slow import stand-in", daemon=True)
    seen: List[bool] = []
    monkeypatch.setattr(_process._state, "start", importing)
    monkeypatch.setattr(_process, "get_participant", lambda: seen.append(importing.is_alive()))
    importing.start()
    assert _runtime.dds_backend() is None
    assert seen == [False]  # the participant was asked for only after the import thread had finished
