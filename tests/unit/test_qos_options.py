"""Unit tests of micros_rt.qos.options: parsing, validation, defaults and the XML-RPC/YAML dict form."""

from __future__ import annotations

import dataclasses
import datetime
import math
import xmlrpc.client
from typing import Any

import pytest

from micros_rt.exceptions import QoSTypeError, QoSValueError, UnsupportedQoSError
from micros_rt.qos.options import (
    DURATION_MAX,
    DURATION_MIN,
    AdvertiseQoSOptions,
    SubscribeQoSOptions,
    TransportPriority,
    priority_dscp,
    priority_socket_priority,
    priority_tos,
    to_seconds,
)

P = TransportPriority


class FakeRospyDuration:
    """Duck-typed stand-in for rospy.Duration (the qos package must not import rospy)."""

    def __init__(self, secs: int, nsecs: int) -> None:
        self.secs, self.nsecs = secs, nsecs

    def to_sec(self) -> float:
        return self.secs + self.nsecs / 1e9


# --- TransportPriority ---------------------------------------------------------------------------


def test_priority_values_follow_the_manual_order() -> None:
    assert [(m.name, int(m)) for m in P] == [
        ("EXTREMELY_LOW", 0),
        ("VERY_LOW", 1),
        ("LOW", 2),
        ("NORMAL", 3),
        ("HIGH", 4),
        ("VERY_HIGH", 5),
        ("EXTREMELY_HIGH", 6),
    ]


@pytest.mark.parametrize(
    "text, expected",
    [
        ("high", P.HIGH),
        ("HIGH", P.HIGH),
        ("High", P.HIGH),
        ("ExtremelyLow", P.EXTREMELY_LOW),
        ("extremely_low", P.EXTREMELY_LOW),
        ("EXTREMELY_LOW", P.EXTREMELY_LOW),
        ("extremely-low", P.EXTREMELY_LOW),
        ("VeryHigh", P.VERY_HIGH),
        ("very_high", P.VERY_HIGH),
        ("ros::Normal", P.NORMAL),
        ("  low ", P.LOW),
        ("ExtremelyHigh", P.EXTREMELY_HIGH),
    ],
)
def test_priority_parse_names(text: str, expected: TransportPriority) -> None:
    assert P.parse(text) is expected


@pytest.mark.parametrize("number", range(7))
def test_priority_parse_ints(number: int) -> None:
    assert P.parse(number) is P(number)
    assert int(P.parse(number)) == number


def test_priority_parse_member_is_identity() -> None:
    assert P.parse(P.VERY_LOW) is P.VERY_LOW


@pytest.mark.parametrize("bad", [-1, 7, 100, "urgent", "", "extremely", "high priority"])
def test_priority_parse_rejects_unknown_values_naming_allowed(bad: Any) -> None:
    with pytest.raises(QoSValueError) as info:
        P.parse(bad)
    message = str(info.value)
    assert repr(bad) in message
    for name in ("EXTREMELY_LOW", "NORMAL", "EXTREMELY_HIGH", "0..6"):
        assert name in message


@pytest.mark.parametrize("bad", [True, False, 3.0, None, [3], b"HIGH"])
def test_priority_parse_rejects_wrong_types(bad: Any) -> None:
    with pytest.raises(QoSTypeError, match="transport_priority"):
        P.parse(bad)


def test_priority_errors_are_plain_value_and_type_errors_too() -> None:
    with pytest.raises(ValueError):
        P.parse("nope")
    with pytest.raises(TypeError):
        P.parse(None)  # type: ignore[arg-type]


def test_dscp_table() -> None:
    assert {p: priority_dscp(p) for p in P} == {
        P.EXTREMELY_LOW: 1,
        P.VERY_LOW: 8,
        P.LOW: 10,
        P.NORMAL: 0,
        P.HIGH: 34,
        P.VERY_HIGH: 40,
        P.EXTREMELY_HIGH: 46,
    }


def test_dscp_fits_six_bits_and_tos_is_shifted() -> None:
    for p in P:
        assert 0 <= priority_dscp(p) <= 63
        assert priority_tos(p) == priority_dscp(p) << 2
        assert priority_tos(p) & 0b11 == 0  # ECN bits untouched
    assert priority_tos(P.EXTREMELY_HIGH) == 0xB8  # the well-known EF TOS byte
    assert priority_tos(P.NORMAL) == 0


def test_socket_priority_table_within_unprivileged_range() -> None:
    table = {p: priority_socket_priority(p) for p in P}
    assert table == {
        P.EXTREMELY_LOW: 1,
        P.VERY_LOW: 2,
        P.LOW: 3,
        P.NORMAL: 0,
        P.HIGH: 4,
        P.VERY_HIGH: 6,
        P.EXTREMELY_HIGH: 6,
    }
    assert all(0 <= v <= 6 for v in table.values())


def test_priority_helpers_accept_names_too() -> None:
    assert priority_dscp("high") == 34  # type: ignore[arg-type]
    assert priority_socket_priority(3) == 0  # type: ignore[arg-type]


# --- durations -----------------------------------------------------------------------------------


def test_duration_constants() -> None:
    assert DURATION_MIN == 0.0
    assert DURATION_MAX == math.inf


@pytest.mark.parametrize(
    "value, seconds",
    [
        (0, 0.0),
        (2, 2.0),
        (0.005, 0.005),
        (math.inf, math.inf),
        (datetime.timedelta(milliseconds=250), 0.25),
        (datetime.timedelta(seconds=3), 3.0),
        (FakeRospyDuration(1, 500_000_000), 1.5),
        (FakeRospyDuration(0, 0), 0.0),
    ],
)
def test_to_seconds_accepts(value: Any, seconds: float) -> None:
    result = to_seconds(value, "latency_budget")
    assert isinstance(result, float)
    assert result == pytest.approx(seconds)


def test_to_seconds_rejects_negative_with_full_message() -> None:
    with pytest.raises(QoSValueError) as info:
        to_seconds(-1, "latency_budget")
    assert str(info.value) == (
        "latency_budget=-1.0 is invalid: expected a duration >= 0 in seconds (float/int), "
        "rospy.Duration or datetime.timedelta"
    )


@pytest.mark.parametrize(
    "bad", [-0.001, float("nan"), -math.inf, datetime.timedelta(seconds=-1), FakeRospyDuration(-1, 0)]
)
def test_to_seconds_rejects_negative_and_nan(bad: Any) -> None:
    with pytest.raises(QoSValueError, match="deadline=.* is invalid: expected a duration >= 0"):
        to_seconds(bad, "deadline")


@pytest.mark.parametrize("bad", [True, False, "1.0", None, [1.0], object()])
def test_to_seconds_rejects_wrong_types(bad: Any) -> None:
    with pytest.raises(QoSTypeError) as info:
        to_seconds(bad, "msg_valid_period")
    assert "msg_valid_period=" in str(info.value)
    assert "rospy.Duration" in str(info.value)


def test_to_seconds_rejects_to_sec_returning_garbage() -> None:
    class Weird:
        def to_sec(self) -> str:
            return "soon"

    with pytest.raises(QoSTypeError, match="to_sec"):
        to_seconds(Weird(), "deadline")


# --- AdvertiseQoSOptions -------------------------------------------------------------------------


def test_advertise_defaults_match_the_manual() -> None:
    o = AdvertiseQoSOptions()
    assert o.transport_priority is P.NORMAL
    assert o.latency_budget == 0.0
    assert o.using_best_effort_protocol is False
    assert o.data_centric_update is False
    assert o.msg_valid_period == math.inf


def test_advertise_positional_order_is_the_struct_order() -> None:
    o = AdvertiseQoSOptions(P.HIGH, 0.01, True, False, 2.0)
    assert (
        o.transport_priority,
        o.latency_budget,
        o.using_best_effort_protocol,
        o.msg_valid_period,
    ) == (P.HIGH, 0.01, True, 2.0)
    assert [f.name for f in dataclasses.fields(AdvertiseQoSOptions)] == [
        "transport_priority",
        "latency_budget",
        "using_best_effort_protocol",
        "data_centric_update",
        "msg_valid_period",
    ]


def test_advertise_normalises_inputs() -> None:
    o = AdvertiseQoSOptions(
        transport_priority="very_high",  # type: ignore[arg-type]
        latency_budget=datetime.timedelta(milliseconds=5),  # type: ignore[arg-type]
        msg_valid_period=FakeRospyDuration(0, 100_000_000),  # type: ignore[arg-type]
    )
    assert o.transport_priority is P.VERY_HIGH
    assert o.latency_budget == pytest.approx(0.005)
    assert o.msg_valid_period == pytest.approx(0.1)
    assert type(o.latency_budget) is float
    assert o == AdvertiseQoSOptions(P.VERY_HIGH, 0.005, msg_valid_period=0.1)


def test_advertise_int_durations_become_float() -> None:
    o = AdvertiseQoSOptions(latency_budget=1, msg_valid_period=3)
    assert type(o.latency_budget) is float and o.latency_budget == 1.0
    assert type(o.msg_valid_period) is float and o.msg_valid_period == 3.0


def test_advertise_is_frozen_and_hashable() -> None:
    o = AdvertiseQoSOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.latency_budget = 1.0  # type: ignore[misc]
    assert hash(o) == hash(AdvertiseQoSOptions())
    assert len({o, AdvertiseQoSOptions(), AdvertiseQoSOptions(transport_priority=P.LOW)}) == 2


def test_advertise_replace_revalidates() -> None:
    o = dataclasses.replace(AdvertiseQoSOptions(), transport_priority="low")  # type: ignore[arg-type]
    assert o.transport_priority is P.LOW
    with pytest.raises(QoSValueError, match="latency_budget"):
        dataclasses.replace(o, latency_budget=-2)


@pytest.mark.parametrize("field_name", ["using_best_effort_protocol", "data_centric_update"])
@pytest.mark.parametrize("bad", [1, 0, "true", None, 1.0])
def test_advertise_bools_must_be_real_bools(field_name: str, bad: Any) -> None:
    with pytest.raises(QoSTypeError) as info:
        AdvertiseQoSOptions(**{field_name: bad})
    assert f"{field_name}={bad!r}" in str(info.value)
    assert "True or False" in str(info.value)


@pytest.mark.parametrize("field_name", ["latency_budget", "msg_valid_period"])
def test_advertise_rejects_negative_durations(field_name: str) -> None:
    with pytest.raises(QoSValueError, match=f"{field_name}=-0.5 is invalid"):
        AdvertiseQoSOptions(**{field_name: -0.5})  # type: ignore[arg-type]


def test_advertise_rejects_zero_valid_period() -> None:
    with pytest.raises(QoSValueError, match="msg_valid_period=0.0 is invalid: every message would expire"):
        AdvertiseQoSOptions(msg_valid_period=0)


def test_advertise_latency_budget_may_be_infinite() -> None:
    assert AdvertiseQoSOptions(latency_budget=math.inf).latency_budget == math.inf


def test_advertise_refuses_data_centric_update() -> None:
    with pytest.raises(UnsupportedQoSError) as info:
        AdvertiseQoSOptions(data_centric_update=True)
    message = str(info.value)
    assert "data_centric_update=True" in message
    assert "no key fields" in message
    assert "queue_size=1" in message and "latch" in message
    assert isinstance(info.value, ValueError)


def test_advertise_rejects_bad_priority() -> None:
    with pytest.raises(QoSValueError, match="transport_priority='urgent'"):
        AdvertiseQoSOptions(transport_priority="urgent")  # type: ignore[arg-type]


# --- SubscribeQoSOptions -------------------------------------------------------------------------


def test_subscribe_defaults_match_the_manual() -> None:
    o = SubscribeQoSOptions()
    assert o.deadline == math.inf
    assert o.deadline_cb is None
    assert o.ordered_by_sending_timestamp is True
    assert o.time_filter_duration == 0.0
    assert o.using_best_effort_protocol is False
    assert o.data_centric_update is False


def test_subscribe_positional_order_is_the_struct_order() -> None:
    assert [f.name for f in dataclasses.fields(SubscribeQoSOptions)] == [
        "deadline",
        "deadline_cb",
        "ordered_by_sending_timestamp",
        "time_filter_duration",
        "using_best_effort_protocol",
        "data_centric_update",
    ]
    cb = lambda _event: None  # noqa: E731
    o = SubscribeQoSOptions(0.5, cb, False, 1.0, True, False)
    assert (o.deadline, o.deadline_cb, o.ordered_by_sending_timestamp) == (0.5, cb, False)
    assert (o.time_filter_duration, o.using_best_effort_protocol) == (1.0, True)


def test_subscribe_normalises_durations() -> None:
    o = SubscribeQoSOptions(
        deadline=FakeRospyDuration(0, 500_000_000),  # type: ignore[arg-type]
        time_filter_duration=datetime.timedelta(seconds=1),  # type: ignore[arg-type]
    )
    assert o.deadline == 0.5 and type(o.deadline) is float
    assert o.time_filter_duration == 1.0 and type(o.time_filter_duration) is float


def test_subscribe_callback_is_not_part_of_equality_or_hash() -> None:
    a = SubscribeQoSOptions(deadline=0.5, deadline_cb=print)
    b = SubscribeQoSOptions(deadline=0.5, deadline_cb=lambda _e: None)
    c = SubscribeQoSOptions(deadline=0.5)
    assert a == b == c
    assert hash(a) == hash(b) == hash(c)
    assert a != SubscribeQoSOptions(deadline=0.6)


def test_subscribe_callback_must_be_callable() -> None:
    with pytest.raises(QoSTypeError, match="deadline_cb=42 is invalid: expected a callable"):
        SubscribeQoSOptions(deadline=1.0, deadline_cb=42)  # type: ignore[arg-type]


def test_subscribe_callback_with_infinite_deadline_would_never_fire() -> None:
    with pytest.raises(QoSValueError, match="never fire"):
        SubscribeQoSOptions(deadline_cb=print)
    with pytest.raises(QoSValueError, match="never fire"):
        SubscribeQoSOptions(deadline=math.inf, deadline_cb=print)


def test_subscribe_finite_deadline_without_callback_is_fine() -> None:
    # The subscriber still counts misses (and logs them) without a callback.
    assert SubscribeQoSOptions(deadline=0.2).deadline == 0.2


def test_subscribe_rejects_zero_deadline() -> None:
    with pytest.raises(QoSValueError, match="deadline=0.0 is invalid"):
        SubscribeQoSOptions(deadline=0)


def test_subscribe_rejects_infinite_time_filter() -> None:
    with pytest.raises(QoSValueError, match="time_filter_duration=inf is invalid"):
        SubscribeQoSOptions(time_filter_duration=math.inf)


@pytest.mark.parametrize("field_name", ["deadline", "time_filter_duration"])
@pytest.mark.parametrize("bad", [-1, float("nan")])
def test_subscribe_rejects_bad_durations(field_name: str, bad: float) -> None:
    with pytest.raises(QoSValueError, match=f"{field_name}=.* is invalid"):
        SubscribeQoSOptions(**{field_name: bad})  # type: ignore[arg-type]


@pytest.mark.parametrize("field_name", ["deadline", "time_filter_duration"])
def test_subscribe_rejects_bool_durations(field_name: str) -> None:
    with pytest.raises(QoSTypeError, match=f"{field_name}=True"):
        SubscribeQoSOptions(**{field_name: True})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "field_name", ["ordered_by_sending_timestamp", "using_best_effort_protocol", "data_centric_update"]
)
@pytest.mark.parametrize("bad", [1, 0, "yes", None])
def test_subscribe_bools_must_be_real_bools(field_name: str, bad: Any) -> None:
    with pytest.raises(QoSTypeError, match=f"{field_name}="):
        SubscribeQoSOptions(**{field_name: bad})


def test_subscribe_refuses_data_centric_update() -> None:
    with pytest.raises(UnsupportedQoSError, match="no key fields"):
        SubscribeQoSOptions(data_centric_update=True)


# --- to_dict / from_dict -------------------------------------------------------------------------


def test_advertise_to_dict_defaults() -> None:
    assert AdvertiseQoSOptions().to_dict() == {
        "transport_priority": "NORMAL",
        "latency_budget": 0.0,
        "using_best_effort_protocol": False,
        "data_centric_update": False,
        "msg_valid_period": "inf",
    }


def test_subscribe_to_dict_defaults_has_no_callback() -> None:
    d = SubscribeQoSOptions(deadline=0.25, deadline_cb=print).to_dict()
    assert d == {
        "deadline": 0.25,
        "ordered_by_sending_timestamp": True,
        "time_filter_duration": 0.0,
        "using_best_effort_protocol": False,
        "data_centric_update": False,
    }
    assert SubscribeQoSOptions().to_dict()["deadline"] == "inf"


ADVERTISE_SAMPLES = [
    AdvertiseQoSOptions(),
    AdvertiseQoSOptions(P.EXTREMELY_HIGH, 0.005, True, False, 0.1),
    AdvertiseQoSOptions(transport_priority=P.EXTREMELY_LOW, latency_budget=math.inf),
]
SUBSCRIBE_SAMPLES = [
    SubscribeQoSOptions(),
    SubscribeQoSOptions(0.5, None, False, 1.0, True, False),
]


@pytest.mark.parametrize("options", ADVERTISE_SAMPLES)
def test_advertise_round_trips_through_xmlrpc(options: AdvertiseQoSOptions) -> None:
    # The real wire: xmlrpc.client refuses inf and enums, so this proves to_dict is XML-RPC-safe.
    wire = xmlrpc.client.dumps((options.to_dict(),))
    (decoded,), _ = xmlrpc.client.loads(wire)
    assert AdvertiseQoSOptions.from_dict(decoded, source="test") == options  # type: ignore[arg-type]


@pytest.mark.parametrize("options", SUBSCRIBE_SAMPLES)
def test_subscribe_round_trips_through_xmlrpc(options: SubscribeQoSOptions) -> None:
    wire = xmlrpc.client.dumps((options.to_dict(),))
    (decoded,), _ = xmlrpc.client.loads(wire)
    assert SubscribeQoSOptions.from_dict(decoded, source="test") == options  # type: ignore[arg-type]


def test_from_dict_missing_keys_keep_defaults() -> None:
    assert AdvertiseQoSOptions.from_dict({}) == AdvertiseQoSOptions()
    assert SubscribeQoSOptions.from_dict({"deadline": 2}) == SubscribeQoSOptions(deadline=2.0)


def test_from_dict_accepts_priority_name_or_int_and_duration_spellings() -> None:
    o = AdvertiseQoSOptions.from_dict(
        {"transport_priority": 5, "latency_budget": "0.002", "msg_valid_period": "Infinity"}
    )
    assert o == AdvertiseQoSOptions(P.VERY_HIGH, 0.002)
    assert AdvertiseQoSOptions.from_dict({"transport_priority": "high"}).transport_priority is P.HIGH
    assert SubscribeQoSOptions.from_dict({"deadline": "DURATION_MAX"}).deadline == math.inf


def test_from_dict_unknown_key_lists_known_keys_and_source() -> None:
    with pytest.raises(QoSValueError) as info:
        AdvertiseQoSOptions.from_dict({"priority": "HIGH"}, source="requestTopic from /talker")
    message = str(info.value)
    assert "'priority'" in message
    assert "requestTopic from /talker" in message
    for key in AdvertiseQoSOptions().to_dict():
        assert key in message


def test_from_dict_rejects_deadline_cb_with_explanation() -> None:
    with pytest.raises(QoSValueError) as info:
        SubscribeQoSOptions.from_dict({"deadline": 1.0, "deadline_cb": "my_cb"})
    assert "deadline_cb" in str(info.value) and "in code" in str(info.value)


def test_from_dict_rejects_bad_values() -> None:
    with pytest.raises(QoSValueError, match="latency_budget='soon' is invalid"):
        AdvertiseQoSOptions.from_dict({"latency_budget": "soon"})
    with pytest.raises(QoSValueError, match="deadline=-1.0 is invalid"):
        SubscribeQoSOptions.from_dict({"deadline": "-1"})


def test_from_dict_rejects_non_mapping() -> None:
    with pytest.raises(QoSTypeError, match="expected a mapping"):
        AdvertiseQoSOptions.from_dict(["transport_priority"])  # type: ignore[arg-type]
