"""Unit tests of micros_rt.qos.mapping: every option and default read back from the Qos object,
plus one in-process Cyclone check that the mapping's request/offered verdicts are real.

No `from __future__ import annotations` here: cyclonedds resolves IdlStruct field annotations at run time.
"""

import itertools
import math
import os
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import pytest
from cyclonedds.qos import Policy, Qos

from micros_rt.exceptions import QoSTypeError, QoSValueError
from micros_rt.qos.compatibility import (
    Compatibility,
    check_compatibility,
    describe_incompatible_policy,
)
from micros_rt.qos.mapping import (
    PUBLISH_BLOCK_TIMEOUT,
    UNBOUNDED_QUEUE_DEPTH,
    duration_ns,
    history_depth,
    plain_reader_qos,
    plain_writer_qos,
    reader_qos,
    writer_qos,
)
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority

INFINITE_NS = 0x7FFFFFFFFFFFFFFF  # DDS_INFINITY
ONE_SECOND_NS = 1_000_000_000
RELIABLE = Policy.Reliability.Reliable(max_blocking_time=ONE_SECOND_NS)
# writers never wait inside Cyclone (it waits holding the GIL); micros_rt waits in Python
WRITER_RELIABLE = Policy.Reliability.Reliable(max_blocking_time=0)


def w(options: AdvertiseQoSOptions | None = None, **kw: Any) -> Qos:
    kw.setdefault("queue_size", 10)
    kw.setdefault("latch", False)
    return writer_qos(options or AdvertiseQoSOptions(), **kw)


def r(options: SubscribeQoSOptions | None = None, **kw: Any) -> Qos:
    kw.setdefault("queue_size", 10)
    return reader_qos(options or SubscribeQoSOptions(), **kw)


# --- helpers -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "seconds, ns",
    [(0.0, 0), (0.005, 5_000_000), (0.1, 100_000_000), (1.5, 1_500_000_000), (math.inf, INFINITE_NS)],
)
def test_duration_ns(seconds: float, ns: int) -> None:
    assert duration_ns(seconds) == ns


@pytest.mark.parametrize("queue_size, depth", [(1, 1), (10, 10), (5000, 5000), (0, 1000), (None, 1000)])
def test_history_depth(queue_size: int | None, depth: int) -> None:
    assert history_depth(queue_size) == depth
    assert UNBOUNDED_QUEUE_DEPTH == 1000


def test_history_depth_rejects_bad_queue_sizes() -> None:
    with pytest.raises(QoSValueError, match="queue_size=-1"):
        history_depth(-1)
    with pytest.raises(QoSTypeError, match="queue_size=True"):
        history_depth(True)
    with pytest.raises(QoSTypeError, match="queue_size=2.5"):
        history_depth(2.5)  # type: ignore[arg-type]


# --- writer_qos ----------------------------------------------------------------------------------


def test_writer_defaults_exactly() -> None:
    assert w() == Qos(
        WRITER_RELIABLE,
        Policy.History.KeepLast(depth=10),
        Policy.Durability.Volatile,
        Policy.LatencyBudget(budget=0),
        Policy.TransportPriority(priority=3),
        Policy.DestinationOrder.BySourceTimestamp,
    )
    assert Policy.Lifespan not in w()  # infinite lifespan = DDS default, left out
    assert Policy.Userdata not in w()
    assert Policy.Deadline not in w()


def test_writer_best_effort() -> None:
    assert w(AdvertiseQoSOptions(using_best_effort_protocol=True))[Policy.Reliability] == (
        Policy.Reliability.BestEffort
    )
    assert w(AdvertiseQoSOptions(using_best_effort_protocol=False))[Policy.Reliability] == WRITER_RELIABLE


@pytest.mark.parametrize("queue_size, depth", [(1, 1), (7, 7)])
@pytest.mark.parametrize("latch", [False, True])
def test_writer_history_keeps_last_queue_size(queue_size: int | None, depth: int, latch: bool) -> None:
    qos = w(queue_size=queue_size, latch=latch)
    assert qos[Policy.History] == Policy.History.KeepLast(depth=depth)
    assert qos[Policy.Reliability] == WRITER_RELIABLE


@pytest.mark.parametrize("queue_size", [0, None])
@pytest.mark.parametrize("latch", [False, True])
def test_writer_lossless_queue_keeps_all_and_blocks(queue_size: int | None, latch: bool) -> None:
    # rospy's queue_size=None is synchronous publishing: nothing dropped, publish() waits instead
    qos = w(queue_size=queue_size, latch=latch)
    assert qos[Policy.History] == Policy.History.KeepAll
    assert qos[Policy.Reliability] == WRITER_RELIABLE  # publish() waits up to PUBLISH_BLOCK_TIMEOUT, in Python
    best_effort = w(AdvertiseQoSOptions(using_best_effort_protocol=True), queue_size=queue_size, latch=latch)
    assert best_effort[Policy.History] == Policy.History.KeepAll
    assert best_effort[Policy.Reliability] == Policy.Reliability.BestEffort


def test_writer_latch_is_transient_local() -> None:
    assert w(latch=True)[Policy.Durability] == Policy.Durability.TransientLocal
    assert w(latch=False)[Policy.Durability] == Policy.Durability.Volatile
    assert w(latch=True, queue_size=1)[Policy.History] == Policy.History.KeepLast(depth=1)


def test_writer_rejects_non_bool_latch() -> None:
    with pytest.raises(QoSTypeError, match="latch=1"):
        w(latch=1)


@pytest.mark.parametrize("priority", list(TransportPriority))
def test_writer_transport_priority_level(priority: TransportPriority) -> None:
    qos = w(AdvertiseQoSOptions(transport_priority=priority))
    assert qos[Policy.TransportPriority] == Policy.TransportPriority(priority=int(priority))


@pytest.mark.parametrize("budget", [0.0, 0.01, 2.0])
def test_writer_latency_budget_is_micros_rt_batching_not_cyclone_async_mode(budget: float) -> None:
    # Cyclone's LatencyBudget > 0 sends every sample from its own thread (slower than no batching);
    # micros_rt batches within the budget itself (micros_rt.transports.dds.batching), so DDS sees 0.
    assert w(AdvertiseQoSOptions(latency_budget=budget))[Policy.LatencyBudget] == Policy.LatencyBudget(budget=0)


@pytest.mark.parametrize("period, ns", [(0.1, 100_000_000), (5.0, 5 * ONE_SECOND_NS)])
def test_writer_lifespan_from_msg_valid_period(period: float, ns: int) -> None:
    assert w(AdvertiseQoSOptions(msg_valid_period=period))[Policy.Lifespan] == Policy.Lifespan(
        lifespan=ns
    )


def test_writer_always_offers_by_source_timestamp() -> None:
    for options in (AdvertiseQoSOptions(), AdvertiseQoSOptions(using_best_effort_protocol=True)):
        for latch in (False, True):
            assert w(options, latch=latch)[Policy.DestinationOrder] == (
                Policy.DestinationOrder.BySourceTimestamp
            )


def test_writer_user_data() -> None:
    assert w(user_data=b"run_id=abc")[Policy.Userdata] == Policy.Userdata(data=b"run_id=abc")
    assert w(user_data=bytearray(b"x"))[Policy.Userdata] == Policy.Userdata(data=b"x")
    assert Policy.Userdata not in w(user_data=b"")
    with pytest.raises(QoSTypeError, match="user_data"):
        w(user_data="run_id=abc")


def test_writer_rejects_wrong_options_type() -> None:
    with pytest.raises(QoSTypeError, match="AdvertiseQoSOptions"):
        writer_qos(SubscribeQoSOptions(), queue_size=1, latch=False)  # type: ignore[arg-type]


def test_writer_full_options() -> None:
    options = AdvertiseQoSOptions(TransportPriority.EXTREMELY_HIGH, 0.002, True, False, 0.5)
    assert w(options, queue_size=3, latch=True, user_data=b"t") == Qos(
        Policy.Reliability.BestEffort,
        Policy.History.KeepLast(depth=3),
        Policy.Durability.TransientLocal,
        Policy.LatencyBudget(budget=0),
        Policy.TransportPriority(priority=6),
        Policy.DestinationOrder.BySourceTimestamp,
        Policy.Lifespan(lifespan=500_000_000),
        Policy.Userdata(data=b"t"),
    )


# --- reader_qos ----------------------------------------------------------------------------------


def test_reader_defaults_exactly() -> None:
    assert r() == Qos(
        RELIABLE,
        Policy.History.KeepAll,
        Policy.Durability.Volatile,
        Policy.LatencyBudget(budget=INFINITE_NS),
        Policy.DestinationOrder.BySourceTimestamp,
    )
    for absent in (Policy.Deadline, Policy.TimeBasedFilter, Policy.Userdata, Policy.Lifespan):
        assert absent not in r()


def test_reader_best_effort() -> None:
    assert r(SubscribeQoSOptions(using_best_effort_protocol=True))[Policy.Reliability] == (
        Policy.Reliability.BestEffort
    )


@pytest.mark.parametrize("queue_size", [1, 100, 0, None])
def test_reader_history_keeps_all(queue_size: int | None) -> None:
    # the subscription keeps the newest queue_size itself, so that every drop is counted
    assert r(queue_size=queue_size)[Policy.History] == Policy.History.KeepAll


def test_reader_transient_local() -> None:
    assert r(transient_local=True)[Policy.Durability] == Policy.Durability.TransientLocal
    assert r(transient_local=False)[Policy.Durability] == Policy.Durability.Volatile
    with pytest.raises(QoSTypeError, match="transient_local"):
        r(transient_local="yes")


def test_reader_destination_order() -> None:
    by_source = r(SubscribeQoSOptions(ordered_by_sending_timestamp=True))
    by_reception = r(SubscribeQoSOptions(ordered_by_sending_timestamp=False))
    assert by_source[Policy.DestinationOrder] == Policy.DestinationOrder.BySourceTimestamp
    assert by_reception[Policy.DestinationOrder] == Policy.DestinationOrder.ByReceptionTimestamp


@pytest.mark.parametrize("seconds, ns", [(1.0, ONE_SECOND_NS), (0.02, 20_000_000)])
def test_reader_time_based_filter(seconds: float, ns: int) -> None:
    qos = r(SubscribeQoSOptions(time_filter_duration=seconds))
    assert qos[Policy.TimeBasedFilter] == Policy.TimeBasedFilter(filter_time=ns)


def test_reader_requests_infinite_latency_budget_whatever_the_options() -> None:
    for options in (SubscribeQoSOptions(), SubscribeQoSOptions(deadline=0.1, time_filter_duration=0.05)):
        assert r(options)[Policy.LatencyBudget] == Policy.LatencyBudget(budget=INFINITE_NS)


def test_reader_never_maps_deadline() -> None:
    qos = r(SubscribeQoSOptions(deadline=0.25, deadline_cb=lambda _e: None))
    assert Policy.Deadline not in qos
    assert qos == r()  # deadline changes nothing on the DDS reader


def test_reader_user_data() -> None:
    assert r(user_data=b"g")[Policy.Userdata] == Policy.Userdata(data=b"g")


def test_reader_rejects_wrong_options_type() -> None:
    with pytest.raises(QoSTypeError, match="SubscribeQoSOptions"):
        reader_qos(AdvertiseQoSOptions(), queue_size=1)  # type: ignore[arg-type]


# --- plain ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("latch", [False, True])
def test_plain_writer_is_the_default_writer(latch: bool) -> None:
    assert plain_writer_qos(queue_size=5, latch=latch) == w(queue_size=5, latch=latch)


def test_plain_reader_orders_by_reception() -> None:
    qos = plain_reader_qos(queue_size=5)
    assert qos[Policy.DestinationOrder] == Policy.DestinationOrder.ByReceptionTimestamp
    assert qos == Qos(
        RELIABLE,
        Policy.History.KeepAll,
        Policy.Durability.Volatile,
        Policy.LatencyBudget(budget=INFINITE_NS),
        Policy.DestinationOrder.ByReceptionTimestamp,
    )
    assert plain_reader_qos(queue_size=1, transient_local=True)[Policy.Durability] == (
        Policy.Durability.TransientLocal
    )


# --- in-process Cyclone: the verdicts hold on a real DDS ------------------------------------------

LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="lo" multicast="false"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto"
    "</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers>"
    '<Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>'
)


@pytest.fixture(scope="module")
def participant() -> Iterator[Any]:
    mp = pytest.MonkeyPatch()
    # Loopback only, set before the participant exists: DDS traffic must never reach the LAN.
    mp.setenv("CYCLONEDDS_URI", LOOPBACK_CONFIG)
    from cyclonedds.domain import DomainParticipant

    domain_id = os.getpid() % 200 + 20
    if str(domain_id) == os.environ.get("ROS_DOMAIN_ID"):
        domain_id += 1  # keep clear of the domain the rest of this test run uses
    dp = DomainParticipant(domain_id)
    try:
        yield dp
    finally:
        mp.undo()


def _take_all(reader: Any, timeout: float) -> list[Any]:
    """Samples taken from ``reader`` once at least one arrived, or [] after ``timeout`` seconds."""
    got: list[Any] = []

    def arrived() -> bool:
        got.extend(reader.take(10))
        return bool(got)

    _wait(arrived, timeout)
    return got


def _wait(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@dataclass(frozen=True)
class Case:
    name: str
    adv: AdvertiseQoSOptions
    sub: SubscribeQoSOptions
    latch: bool = False
    transient_local: bool = False


BE_PUB = AdvertiseQoSOptions(using_best_effort_protocol=True)
BE_SUB = SubscribeQoSOptions(using_best_effort_protocol=True)
CASES = [
    Case("defaults", AdvertiseQoSOptions(), SubscribeQoSOptions()),
    Case("latency_budget_10ms", AdvertiseQoSOptions(latency_budget=0.01), SubscribeQoSOptions()),
    Case("latency_budget_big", AdvertiseQoSOptions(latency_budget=30.0), SubscribeQoSOptions()),
    Case("reliable_pub_be_sub", AdvertiseQoSOptions(), BE_SUB),
    Case("be_pub_be_sub", BE_PUB, BE_SUB),
    Case("be_pub_reliable_sub", BE_PUB, SubscribeQoSOptions()),
    Case("reception_order_sub", AdvertiseQoSOptions(), SubscribeQoSOptions(ordered_by_sending_timestamp=False)),
    Case("deadline_sub", AdvertiseQoSOptions(), SubscribeQoSOptions(deadline=0.05)),
    Case("time_filter_sub", AdvertiseQoSOptions(), SubscribeQoSOptions(time_filter_duration=0.5)),
    Case("priority_and_lifespan", AdvertiseQoSOptions(TransportPriority.EXTREMELY_HIGH, msg_valid_period=30.0), SubscribeQoSOptions()),
    Case("latched_pair", AdvertiseQoSOptions(), SubscribeQoSOptions(), latch=True, transient_local=True),
    Case("latched_pub_volatile_sub", AdvertiseQoSOptions(), SubscribeQoSOptions(), latch=True),
    Case("volatile_pub_latched_sub", AdvertiseQoSOptions(), SubscribeQoSOptions(), transient_local=True),
]


def test_cyclone_matches_exactly_what_check_compatibility_predicts(participant: Any) -> None:
    from cyclonedds.idl import IdlStruct
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    @dataclass
    class Probe(IdlStruct, typename="micros_rt_test::Probe"):
        value: int

    pairs: list[tuple[Case, Any, Any, Compatibility]] = []  # cyclonedds is untyped
    for i, case in enumerate(CASES):
        topic = Topic(participant, f"micros_rt_mapping_{os.getpid()}_{i}", Probe)
        writer = DataWriter(
            participant, topic, qos=writer_qos(case.adv, queue_size=5, latch=case.latch)
        )
        reader = DataReader(
            participant,
            topic,
            qos=reader_qos(case.sub, queue_size=5, transient_local=case.transient_local),
        )
        verdict = check_compatibility(
            case.adv,
            case.sub,
            topic=case.name,
            offered_latch=case.latch,
            requested_transient_local=case.transient_local,
        )
        pairs.append((case, writer, reader, verdict))

    expected_incompatible = {"be_pub_reliable_sub": 11, "volatile_pub_latched_sub": 2}
    assert {c.name for c, _, _, v in pairs if not v.compatible} == set(expected_incompatible)

    # Matching is decided in discovery; wait until every pair has either matched or been refused.
    def settled() -> bool:
        return all(
            reader.get_subscription_matched_status().current_count == 1
            or reader.get_requested_incompatible_qos_status().total_count > 0
            for _, _, reader, _ in pairs
        )

    assert _wait(settled, timeout=10.0), "discovery did not settle within 10 s"
    for _, writer, _, _ in pairs:
        writer.write(Probe(value=42))

    for case, _, reader, verdict in pairs:
        if verdict.compatible:
            got = _take_all(reader, timeout=5.0)
            assert [s.value for s in got] == [42], case.name
            assert reader.get_requested_incompatible_qos_status().total_count == 0, case.name
        else:
            status = reader.get_requested_incompatible_qos_status()
            assert status.total_count >= 1, case.name
            assert status.last_policy_id == expected_incompatible[case.name], case.name
            assert reader.get_subscription_matched_status().current_count == 0, case.name
            assert reader.take(10) == [], case.name
            words = describe_incompatible_policy(status.last_policy_id, topic=case.name, side="reader")
            assert verdict.option is not None and verdict.option in words, (case.name, words)


def test_cyclone_latched_message_reaches_late_joiner(participant: Any) -> None:
    from cyclonedds.idl import IdlStruct
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    @dataclass
    class Latched(IdlStruct, typename="micros_rt_test::Latched"):
        value: int

    topic = Topic(participant, f"micros_rt_latched_{os.getpid()}", Latched)
    writer = DataWriter(participant, topic, qos=plain_writer_qos(queue_size=1, latch=True))
    for value in (1, 2, 3):
        writer.write(Latched(value=value))
    # The reader joins after the writes: only TRANSIENT_LOCAL on both ends delivers the last one.
    reader = DataReader(participant, topic, qos=plain_reader_qos(queue_size=1, transient_local=True))
    assert [s.value for s in _take_all(reader, timeout=5.0)] == [3]


def test_cases_cover_every_option_in_both_directions() -> None:
    # Guard against a new option slipping past the Cyclone check above.
    adv_changed = {
        name
        for c in CASES
        for name, value in c.adv.to_dict().items()
        if value != AdvertiseQoSOptions().to_dict()[name]
    }
    sub_changed = {
        name
        for c in CASES
        for name, value in c.sub.to_dict().items()
        if value != SubscribeQoSOptions().to_dict()[name]
    }
    assert adv_changed == {"transport_priority", "latency_budget", "using_best_effort_protocol", "msg_valid_period"}
    assert sub_changed == {"deadline", "ordered_by_sending_timestamp", "time_filter_duration", "using_best_effort_protocol"}
    assert set(itertools.product([False, True], repeat=2)) <= {(c.latch, c.transient_local) for c in CASES} | {(False, False)}
