"""Unit tests of micros_rt.qos.compatibility: every option, both directions, and the words used."""

from __future__ import annotations

import math
from typing import Any

import pytest

from micros_rt.exceptions import QoSTypeError, QoSValueError
from micros_rt.qos.compatibility import (
    POLICY_NAMES,
    Compatibility,
    check_compatibility,
    describe_incompatible_policy,
)
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority

PUB = AdvertiseQoSOptions
SUB = SubscribeQoSOptions


def check(pub: AdvertiseQoSOptions, sub: SubscribeQoSOptions, **kw: Any) -> Compatibility:
    return check_compatibility(pub, sub, topic="/chatter", **kw)


def test_defaults_are_compatible() -> None:
    verdict = check(PUB(), SUB())
    assert verdict == Compatibility(
        compatible=True, option=None, reason="topic /chatter: publisher and subscriber QoS are compatible"
    )
    assert bool(verdict) is True


# --- reliability ---------------------------------------------------------------------------------


def test_best_effort_publisher_reliable_subscriber_clashes() -> None:
    verdict = check(PUB(using_best_effort_protocol=True), SUB(using_best_effort_protocol=False))
    assert verdict.compatible is False
    assert bool(verdict) is False
    assert verdict.option == "using_best_effort_protocol"
    reason = verdict.reason
    assert "/chatter" in reason
    assert "publisher uses best-effort" in reason and "using_best_effort_protocol=True" in reason
    assert "subscriber requires reliable" in reason and "using_best_effort_protocol=False" in reason
    assert "Set using_best_effort_protocol=True on the subscriber, or False on the publisher" in reason


@pytest.mark.parametrize(
    "pub_be, sub_be", [(False, False), (False, True), (True, True)], ids=["rel-rel", "rel-be", "be-be"]
)
def test_other_reliability_combinations_are_compatible(pub_be: bool, sub_be: bool) -> None:
    verdict = check(PUB(using_best_effort_protocol=pub_be), SUB(using_best_effort_protocol=sub_be))
    assert verdict.compatible is True
    assert verdict.option is None


# --- durability (latch) --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "latch, transient_local, ok",
    [(False, False, True), (True, False, True), (True, True, True), (False, True, False)],
)
def test_latch_combinations(latch: bool, transient_local: bool, ok: bool) -> None:
    verdict = check(PUB(), SUB(), offered_latch=latch, requested_transient_local=transient_local)
    assert verdict.compatible is ok
    if not ok:
        assert verdict.option == "latch"
        assert "latch=True" in verdict.reason and "/chatter" in verdict.reason


def test_reliability_is_reported_before_latch() -> None:
    verdict = check(
        PUB(using_best_effort_protocol=True), SUB(), offered_latch=False, requested_transient_local=True
    )
    assert verdict.option == "using_best_effort_protocol"


# --- options that never clash, each tested in both directions --------------------------------------


@pytest.mark.parametrize("priority", list(TransportPriority))
def test_transport_priority_never_clashes(priority: TransportPriority) -> None:
    assert check(PUB(transport_priority=priority), SUB()).compatible
    assert check(PUB(transport_priority=priority), SUB(using_best_effort_protocol=True)).compatible


@pytest.mark.parametrize("budget", [0.0, 0.001, 0.5, 60.0, math.inf])
@pytest.mark.parametrize("sub", [SUB(), SUB(deadline=0.01), SUB(time_filter_duration=0.1)])
def test_latency_budget_never_clashes(budget: float, sub: SubscribeQoSOptions) -> None:
    # Readers request an infinite latency budget, so any offer is <= the request.
    assert check(PUB(latency_budget=budget), sub).compatible


@pytest.mark.parametrize("ordered", [True, False])
@pytest.mark.parametrize("pub", [PUB(), PUB(using_best_effort_protocol=True)])
def test_destination_order_never_clashes(ordered: bool, pub: AdvertiseQoSOptions) -> None:
    # Writers offer BY_SOURCE_TIMESTAMP, the strongest kind; readers request either.
    sub = SUB(ordered_by_sending_timestamp=ordered, using_best_effort_protocol=True)
    assert check(pub, sub).compatible


@pytest.mark.parametrize("deadline", [0.001, 0.5, math.inf])
@pytest.mark.parametrize("period", [0.001, 1.0, math.inf])
def test_deadline_never_clashes_with_any_publisher(deadline: float, period: float) -> None:
    # Not mapped onto DDS: micros_rt enforces it in the subscriber.
    assert check(PUB(msg_valid_period=period), SUB(deadline=deadline)).compatible


@pytest.mark.parametrize("filter_s", [0.0, 0.01, 5.0])
def test_time_filter_never_clashes(filter_s: float) -> None:
    assert check(PUB(), SUB(time_filter_duration=filter_s)).compatible
    assert check(PUB(latency_budget=1.0), SUB(time_filter_duration=filter_s)).compatible


@pytest.mark.parametrize("period", [0.001, 0.1, 100.0, math.inf])
def test_msg_valid_period_never_clashes(period: float) -> None:
    assert check(PUB(msg_valid_period=period), SUB()).compatible
    assert check(PUB(msg_valid_period=period), SUB(deadline=0.5, time_filter_duration=1.0)).compatible


def test_everything_changed_but_reliability_is_compatible() -> None:
    pub = PUB(TransportPriority.EXTREMELY_LOW, 10.0, False, False, 0.01)
    sub = SUB(0.001, lambda _e: None, False, 2.0, False, False)
    assert check(pub, sub, offered_latch=True, requested_transient_local=True).compatible


def test_check_is_pure_and_repeatable() -> None:
    pub, sub = PUB(using_best_effort_protocol=True), SUB()
    assert check(pub, sub) == check(pub, sub)
    assert pub == PUB(using_best_effort_protocol=True) and sub == SUB()


def test_check_rejects_swapped_arguments() -> None:
    with pytest.raises(QoSTypeError, match="offered="):
        check_compatibility(SUB(), SUB(), topic="/t")  # type: ignore[arg-type]
    with pytest.raises(QoSTypeError, match="requested="):
        check_compatibility(PUB(), PUB(), topic="/t")  # type: ignore[arg-type]


# --- describe_incompatible_policy ----------------------------------------------------------------


def test_policy_ids_follow_cyclone_numbering() -> None:
    # dds_qos_policy_id_t; 2, 4, 5, 11 and 12 were observed from a real Cyclone 11 reader.
    assert POLICY_NAMES[2] == "DURABILITY"
    assert POLICY_NAMES[4] == "DEADLINE"
    assert POLICY_NAMES[5] == "LATENCYBUDGET"
    assert POLICY_NAMES[11] == "RELIABILITY"
    assert POLICY_NAMES[12] == "DESTINATIONORDER"
    assert POLICY_NAMES[25] == "DATA_REPRESENTATION"
    assert sorted(POLICY_NAMES) == list(range(26))


@pytest.mark.parametrize(
    "policy, option",
    [
        (11, "using_best_effort_protocol"),
        (2, "latch"),
        (5, "latency_budget"),
        (12, "ordered_by_sending_timestamp"),
        (4, "deadline"),
    ],
)
def test_describe_names_the_micros_rt_option(policy: int, option: str) -> None:
    text = describe_incompatible_policy(policy, topic="/scan", side="subscriber")
    assert text.startswith("topic /scan: the subscriber cannot connect to a publisher")
    assert f"DDS {POLICY_NAMES[policy]}, micros_rt option {option}" in text


def test_describe_reliability_full_sentence() -> None:
    assert describe_incompatible_policy(11, topic="/scan", side="reader") == (
        "topic /scan: the subscriber cannot connect to a publisher because their QoS is incompatible "
        "(DDS RELIABILITY, micros_rt option using_best_effort_protocol): the publisher is best effort "
        "but the subscriber requires reliable delivery; set using_best_effort_protocol=True on the "
        "subscriber, or False on the publisher."
    )


@pytest.mark.parametrize("side", ["publisher", "writer", "offered", "Publisher "])
def test_describe_from_the_writer_side(side: str) -> None:
    text = describe_incompatible_policy(11, topic="/scan", side=side)
    assert "the publisher cannot connect to a subscriber" in text


@pytest.mark.parametrize(
    "name", ["RELIABILITY", "reliability", "Reliability", "DDS_RELIABILITY_QOS_POLICY_ID"]
)
def test_describe_accepts_policy_names(name: str) -> None:
    assert describe_incompatible_policy(name, topic="/t", side="reader") == describe_incompatible_policy(
        11, topic="/t", side="reader"
    )


@pytest.mark.parametrize("policy", [6, 8, 10, 24, "DATA_REPRESENTATION"])
def test_describe_policies_without_micros_rt_option(policy: int | str) -> None:
    text = describe_incompatible_policy(policy, topic="/t", side="reader")
    assert "no micros_rt option" in text
    assert text.endswith(".")


def test_describe_unknown_policy_id_still_says_something_useful() -> None:
    text = describe_incompatible_policy(99, topic="/t", side="writer")
    assert "policy #99" in text and "probably not micros_rt" in text


def test_describe_rejects_bad_side_and_type() -> None:
    with pytest.raises(QoSValueError, match="side='both'"):
        describe_incompatible_policy(11, topic="/t", side="both")
    with pytest.raises(QoSTypeError):
        describe_incompatible_policy(1.5, topic="/t", side="reader")  # type: ignore[arg-type]
    with pytest.raises(QoSTypeError):
        describe_incompatible_policy(True, topic="/t", side="reader")
