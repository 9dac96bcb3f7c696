"""rospy's registration races, and micros_rt's fixes (transports/tcpros/patches: _merging_publisher_update, _OneAtATime).

rospy's RegManager queues publisher lists (from ``registerSubscriber``'s answer and from the master's
``publisherUpdate`` calls) and its thread connects to the newest list of a topic, discarding the older ones. When
the answer to ``registerSubscriber`` (read before the publisher registered: empty) is queued after the master's
``publisherUpdate`` naming the publisher, the publisher is never connected. These tests use rospy's own class and
take updates the way its thread does (``RegManager.run``: pop the last, drop the others of that topic).
"""

from __future__ import annotations

import threading
import time
from typing import Any, Dict, List, Optional, Tuple

import rospy.impl.registration as registration

from micros_rt.transports.tcpros import patches as rospy_compat


def _reg_manager() -> Any:
    reg = object.__new__(registration.RegManager)  # only the queue: no handler, no thread
    reg.cond = threading.Condition()
    reg.updates = []
    return reg


def _take(reg: Any) -> Optional[Tuple[str, List[str]]]:
    """What RegManager.run connects to next, as it takes it."""
    if not reg.updates:
        return None
    topic, uris = reg.updates.pop()
    reg.updates = [x for x in reg.updates if x[0] != topic]
    return topic, uris




def test_rospys_own_queue_loses_a_publisher_when_a_stale_list_comes_second() -> None:
    # the race as it is in stock rospy (the reason for the fix): recorded so that a rospy that fixes it shows here
    reg = _reg_manager()
    if registration.RegManager.publisher_update is rospy_compat._merging_publisher_update:
        return  # installed in this process by another test: the original is not reachable any more
    registration.RegManager.publisher_update(reg, "/t", ["http://pub:1/"])  # the master's publisherUpdate
    registration.RegManager.publisher_update(reg, "/t", [])                 # registerSubscriber's late answer
    assert _take(reg) == ("/t", [])


def test_a_stale_list_queued_after_a_newer_one_no_longer_erases_its_publisher() -> None:
    reg = _reg_manager()
    rospy_compat._merging_publisher_update(reg, "/t", ["http://pub:1/"])
    rospy_compat._merging_publisher_update(reg, "/t", [])
    rospy_compat._merging_publisher_update(reg, "/other", ["http://pub:3/"])
    assert _take(reg) == ("/other", ["http://pub:3/"])
    assert _take(reg) == ("/t", ["http://pub:1/"])
    assert _take(reg) is None


def test_queued_lists_of_a_topic_are_joined_in_order_without_repeats() -> None:
    reg = _reg_manager()
    rospy_compat._merging_publisher_update(reg, "/t", ["http://a:1/", "http://b:1/"])
    rospy_compat._merging_publisher_update(reg, "/t", ["http://b:1/", "http://c:1/"])
    assert _take(reg) == ("/t", ["http://b:1/", "http://c:1/", "http://a:1/"])
    # once taken, an update stands alone again (rospy's thread has connected to what it named)
    rospy_compat._merging_publisher_update(reg, "/t", ["http://d:1/"])
    assert _take(reg) == ("/t", ["http://d:1/"])


def test_install_puts_the_merging_update_in_rospys_registration_manager() -> None:
    finders = rospy_compat._find_publication, rospy_compat._find_subscription
    try:
        rospy_compat.install(lambda topic: None, lambda topic: None)
        assert registration.RegManager.publisher_update is rospy_compat._merging_publisher_update
    finally:
        rospy_compat.install(*finders)  # whatever this process had (another test's node): as it was


def test_connections_to_one_publisher_are_made_one_at_a_time() -> None:
    # rospy's thread connects to every URI of every list it takes: [B] then [A, B] connects to B twice at once,
    # and rospy keeps the second connection, closing the first with what B had written into it
    active: Dict[str, int] = {}
    most: Dict[str, int] = {}
    lock = threading.Lock()
    entered = threading.Barrier(3, timeout=10)

    def original(handler: Any, topic: str, uri: str) -> Tuple[int, str, int]:
        with lock:
            active[uri] = active.get(uri, 0) + 1
            most[uri] = max(most.get(uri, 0), active[uri])
        time.sleep(0.05)
        with lock:
            active[uri] -= 1
        return 1, "connected", 0

    finders = rospy_compat._find_publication, rospy_compat._find_subscription
    rospy_compat.install(finders[0], lambda topic: None)   # a plain rospy subscription: rospy's own connect
    try:
        connect = rospy_compat._wrapped_connect_topic(original)

        def run(uri: str) -> None:
            entered.wait()
            connect(None, "/t", uri)

        threads = [threading.Thread(target=run, args=(uri,)) for uri in ("http://b:1/", "http://b:1/", "http://a:1/")]
        for t in threads:
            t.start()
        for t in threads:
            t.join(10)
    finally:
        rospy_compat.install(*finders)
    assert most == {"http://b:1/": 1, "http://a:1/": 1}, most
    assert not rospy_compat._connecting._held   # nothing kept once the connections are made
