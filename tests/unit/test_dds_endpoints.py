"""A DDS writer's view of its matched readers, on live Cyclone endpoints in this process (loopback, this
run's domain; no master): the GUIDs follow readers that come and go, also with several threads asking."""

from __future__ import annotations

import threading
from typing import List, Set

from std_msgs.msg import String

import harness

from micros_rt.transports.dds.endpoints import DDSReader, DDSWriter
from micros_rt.transports.dds.participant import get_participant
from micros_rt.transports.dds.types import dds_type_for
from micros_rt.qos.mapping import plain_reader_qos, plain_writer_qos


def test_matched_reader_guids_follow_readers_that_come_and_go_under_concurrent_callers() -> None:
    participant = get_participant()
    assert participant is not None
    dds_type = dds_type_for(String)
    topic = "rt/micros_rt_test_matched_guids"
    writer = DDSWriter(participant, topic, dds_type, plain_writer_qos(queue_size=10, latch=False))
    readers = [DDSReader(participant, topic, dds_type, plain_reader_qos(queue_size=10)) for _ in range(3)]
    try:
        want: Set[str] = {r.guid for r in readers}
        harness.wait_until(lambda: set(writer.matched_reader_guids()) == want, 10, message="the three readers matched")

        errors: List[BaseException] = []
        stop = threading.Event()

        def ask() -> None:  # housekeeping, get_num_connections() and a publish timeout ask from their threads;
            # a reader unmatched between the handles and their data once raised IndexError out of it
            try:
                while not stop.is_set():
                    guids = writer.matched_reader_guids()
                    assert len(guids) == len(set(guids)), guids
            except BaseException as exc:  # noqa: BLE001 (reported below)
                errors.append(exc)

        askers = [threading.Thread(target=ask) for _ in range(4)]
        for t in askers:
            t.start()
        for _ in range(10):  # readers matched and unmatched while the askers run
            extra = DDSReader(participant, topic, dds_type, plain_reader_qos(queue_size=10))
            harness.wait_until(lambda: extra.guid in writer.matched_reader_guids(), 10, message="a new reader matched")
            extra.close()
            harness.wait_until(lambda: extra.guid not in writer.matched_reader_guids(), 10,
                               message="a closed reader unmatched")
        gone = readers.pop()
        gone.close()
        want_after = {r.guid for r in readers}
        harness.wait_until(lambda: set(writer.matched_reader_guids()) == want_after, 10,
                           message="the two remaining readers, the closed one gone")
        stop.set()
        for t in askers:
            t.join(10)
        assert not errors, errors
        assert gone.guid not in writer.matched_reader_guids()
    finally:
        for r in readers:
            r.close()
        writer.close()
