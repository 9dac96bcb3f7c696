"""A DDS writer's view of its matched readers, on live Cyclone endpoints in this process (loopback, this
run's domain; no master): the GUIDs follow readers that come and go, also with several threads asking."""

from __future__ import annotations

import threading
import time
from typing import Any, Dict, List, Optional, Set


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


def test_large_samples_are_taken_with_the_gil_released_and_arrive_the_same() -> None:
    """A reader whose last sample was large takes the next through dds_takecdr (Cyclone's copy with the GIL
    released); the bytes are the ones ddspy_take gives, and small samples go back to ddspy_take."""
    from micros_rt.transports.dds import endpoints

    participant = get_participant()
    assert participant is not None
    dds_type = dds_type_for(String)
    topic = "rt/micros_rt_test_released_take"
    writer = DDSWriter(participant, topic, dds_type, plain_writer_qos(queue_size=10, latch=False))
    reader = DDSReader(participant, topic, dds_type, plain_reader_qos(queue_size=10))
    try:
        harness.wait_until(lambda: writer.matched_count == 1, 10, message="the reader matched")
        big = String(data="x" * 200_000 + "end")

        def one() -> bytes:
            taken: List[bytes] = []

            def took() -> bool:
                taken.extend(d for d, i in reader.take_raw(8) if i.valid_data)
                return bool(taken)
            harness.wait_until(took, 10, interval=0.01, message="a sample taken")
            assert len(taken) == 1, len(taken)
            return taken[0]

        writer.write_serialized(dds_type.encode(big))
        first = one()                                  # ddspy_take (nothing large seen yet)
        assert reader._large and isinstance(first, bytes)
        writer.write_serialized(dds_type.encode(big))
        second = one()                                 # dds_takecdr, copied without the GIL
        assert isinstance(second, bytes) and second == first
        assert dds_type.decode(second).data == big.data
        writer.write_serialized(dds_type.encode(String(data="small")))
        assert dds_type.decode(one()).data == "small"  # taken the released way (the last one was large)...
        assert not reader._large                       # ...and the next by ddspy_take again
        assert endpoints._takecdr is not None
    finally:
        reader.close()
        writer.close()


def test_a_writer_read_as_untagged_is_read_again_and_a_tagged_one_is_not() -> None:
    """A relay import refuses untagged writers: a writer's match data read once without its micros_rt tag must not
    make it untagged for good (it refused all 1,809 samples of a tagged exporter in a suite run)."""
    from cyclonedds.qos import Policy, Qos

    from micros_rt.transports.dds import endpoints
    from micros_rt.transports.dds.endpoints import make_user_data

    class Data:
        def __init__(self, user_data: bytes) -> None:
            self.key, self.participant_key = "writer-guid", "participant-guid"
            self.qos = Qos(Policy.Userdata(user_data)) if user_data else Qos()

    answers = [Data(b""), Data(make_user_data(graph="g", relay="robot_a"))]
    reads: List[int] = []

    class Reader:
        def get_matched_publication_data(self, handle: int) -> Data:
            reads.append(handle)
            return answers[min(len(reads), len(answers)) - 1]

    reader: Any = object.__new__(DDSReader)
    reader._writers, reader._recheck, reader._lock, reader._reader = {}, {}, threading.Lock(), Reader()

    def tag() -> Optional[Dict[str, str]]:
        info = reader.writer_info(7)
        assert info is not None
        return info.tag  # type: ignore[no-any-return]

    assert tag() is None                         # the first read: no tag
    assert tag() is None and len(reads) == 1     # within UNTAGGED_RECHECK: the cached answer
    assert 0 < reader._recheck[7] - time.monotonic() <= endpoints.UNTAGGED_RECHECK
    reader._recheck[7] = 0.0                     # UNTAGGED_RECHECK passed
    assert tag() == {"graph": "g", "relay": "robot_a"} and len(reads) == 2
    assert 7 not in reader._recheck
    assert tag() is not None and len(reads) == 2  # a tagged writer is never read again
