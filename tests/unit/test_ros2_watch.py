"""The host's ROS 2 watcher (``auto`` visibility): one lock holder per host, user and domain, found from
/proc/locks, and micros_rt's participants told from everyone else's by their user data."""

from __future__ import annotations

import os

from micros_rt.transports.dds.watch import (PARTICIPANT_USER_DATA, Ros2Watch, is_micros_rt_participant, watch_paths,
                                            watcher_pid)

DOMAIN = 232  # no test run's own domain (1..220)


def test_paths_name_user_network_namespace_and_domain() -> None:
    lock, marker = watch_paths(DOMAIN)
    net = str(os.stat("/proc/self/ns/net").st_ino)
    assert lock.endswith(f"_u{os.getuid()}_n{net}_d{DOMAIN}.lock") and marker == lock[:-len(".lock")] + ".seen"
    assert watch_paths(DOMAIN - 1)[0] != lock


def test_participants_are_told_apart_by_user_data() -> None:
    assert is_micros_rt_participant(PARTICIPANT_USER_DATA)
    assert PARTICIPANT_USER_DATA.startswith(b"enclave=/;")  # what rmw reads stays there
    for foreign in (None, b"", b"enclave=/;", b"micros_rt=0;"):
        assert not is_micros_rt_participant(foreign)


def test_one_watcher_at_a_time_and_the_next_takes_over() -> None:
    first, second = Ros2Watch(DOMAIN, lambda: None), Ros2Watch(DOMAIN, lambda: None)
    try:
        assert first._take_lock()
        assert not second._take_lock() and not second.failed  # busy, not broken: it tries again next tick
        assert watcher_pid(first.lock_path) == os.getpid()
        first.close()
        assert second._take_lock()
        # a watcher whose DDS cannot start gives the watch up at once, and says so only once
        second.close()
        assert not first.poll() and first.failed and watcher_pid(first.lock_path) is None
    finally:
        first.close()
        second.close()
        os.unlink(first.lock_path)
