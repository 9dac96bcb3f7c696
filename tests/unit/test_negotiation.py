"""Unit tests of micros_rt.negotiation: offer/answer messages, decide(), choose_protocol(), RateLimitedLog.

Pure and in-process: no rospy, no rosmaster, no DDS.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import xmlrpc.client
from typing import Any, Callable, Dict, List, Optional, Tuple

import pytest

from micros_rt.negotiation.choose import Choice, OfferJudge, choose_protocol
from micros_rt.negotiation.decide import PublicationFacts, Verdict
from micros_rt.negotiation.messages import MalformedNegotiationError
from micros_rt.transports.dds.offer import MAX_PENDING_DDS_OFFERS, DDSAnswer, DDSOffer, dds_transport, decide, is_guid
from micros_rt.negotiation.protocol import DDS, MAX_FIELD_CHARS, TCPROS
from micros_rt.ratelimit import RateLimitedLog
from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.qos.options import TransportPriority

GUID_R = "01106fda-d45a-29f3-b1ee-b181000001c1"
GUID_P = "01106fda-d45a-29f3-b1ee-b18100000001"
GUID_W = "01106fda-d45a-29f3-b1ee-b18100000102"
TYPE = "std_msgs::msg::dds_::String_"
MD5 = "992ce8a1687cec8c8bd883ec73ca41d1"


def make_offer(**changes: Any) -> DDSOffer:
    base = DDSOffer(domain=0, topic="rt/chatter", type_name=TYPE, md5=MD5, qos=SubscribeQoSOptions(),
                    reader=GUID_R, participant=GUID_P, graph="run@http://127.0.0.1:11311/")
    return dataclasses.replace(base, **changes)


def make_answer(**changes: Any) -> DDSAnswer:
    base = DDSAnswer(writer=GUID_W, participant=GUID_P, latch=False, qos=AdvertiseQoSOptions(), node="/talker")
    return dataclasses.replace(base, **changes)


def offer_params(**changes: Any) -> Dict[str, Any]:
    params = make_offer().to_xmlrpc()[1]
    assert isinstance(params, dict)
    params.update(changes)
    return params


def answer_params(**changes: Any) -> Dict[str, Any]:
    params = make_answer().params()
    params.update(changes)
    return params


def wire(value: Any) -> Any:
    """``value`` after a real XML-RPC marshal and unmarshal (what the other node reads)."""
    text = xmlrpc.client.dumps((value,), methodresponse=True, allow_none=False)
    (back,), _ = xmlrpc.client.loads(text)
    return back


# --------------------------------------------------------------------------------------------- messages


OFFERS = [
    make_offer(),
    make_offer(transient_local=True),
    make_offer(follow=True),
    make_offer(domain=232, md5="*"),
    make_offer(domain=-(2 ** 31)),
    make_offer(domain=2 ** 31 - 1),
    make_offer(qos=SubscribeQoSOptions(deadline=0.25, ordered_by_sending_timestamp=False,
                                       time_filter_duration=0.1, using_best_effort_protocol=True)),
    make_offer(topic="x" * MAX_FIELD_CHARS, graph=""),
]


@pytest.mark.parametrize("offer", OFFERS)
def test_offer_round_trip(offer: DDSOffer) -> None:
    entry = offer.to_xmlrpc()
    assert entry[0] == DDS and isinstance(entry, list)
    assert DDSOffer.from_xmlrpc(entry[1]) == offer


@pytest.mark.parametrize("offer", OFFERS)
def test_offer_round_trip_over_xmlrpc_wire(offer: DDSOffer) -> None:
    entry = wire(offer.to_xmlrpc())
    assert entry[0] == DDS
    back = DDSOffer.from_xmlrpc(entry[1])
    assert back == offer
    assert back.qos.to_dict() == offer.qos.to_dict()


ANSWERS = [
    make_answer(),
    make_answer(latch=True, node=""),
    make_answer(qos=AdvertiseQoSOptions(transport_priority=TransportPriority.HIGH, latency_budget=0.005,
                                        using_best_effort_protocol=True, msg_valid_period=0.5)),
    make_answer(via="robot_a", node="/relay_robot_b"),
    make_answer(via="robot_a", node="/relay_robot_b", topic="/robot_a/other"),
]


@pytest.mark.parametrize("answer", ANSWERS)
def test_answer_round_trip(answer: DDSAnswer) -> None:
    entry = answer.to_xmlrpc()
    assert entry == [DDS, answer.params()]
    assert DDSAnswer.from_xmlrpc(entry[1]) == answer
    assert DDSAnswer.from_xmlrpc(wire(entry)[1]) == answer


def test_answer_node_is_optional() -> None:
    params = answer_params()
    del params["node"]
    assert DDSAnswer.from_xmlrpc(params).node == ""


def test_answer_via_is_optional_and_sent_only_when_set() -> None:
    # a subscriber of an older micros_rt reads the answer of a delegating publisher as an ordinary one
    assert "via" not in make_answer().params() and DDSAnswer.from_xmlrpc(answer_params()).via == ""
    assert "topic" not in make_answer(via="robot_a").params() and DDSAnswer.from_xmlrpc(answer_params()).topic == ""
    assert DDSOffer.from_xmlrpc({k: v for k, v in offer_params().items() if k != "follow"}).follow is False
    for bad in ("robot_a/chatter", "/robot a", "/a//b", "/a/~b", "/a/", 5):
        with pytest.raises(MalformedNegotiationError, match="topic"):
            DDSAnswer.from_xmlrpc({**answer_params(), "via": "robot_a", "topic": bad})
    for good in ("/robot_a/chatter", "/_micros_rt_relay/x", "/robot_1/2d_map"):
        assert DDSAnswer.from_xmlrpc({**answer_params(), "via": "robot_a", "topic": good}).topic == good
    with pytest.raises(MalformedNegotiationError, match="via"):
        DDSAnswer.from_xmlrpc({**answer_params(), "via": 7})


def test_bool_fields_default_to_false_when_missing() -> None:
    params = offer_params()
    del params["transient_local"]
    assert DDSOffer.from_xmlrpc(params).transient_local is False
    aparams = answer_params()
    del aparams["latch"]
    assert DDSAnswer.from_xmlrpc(aparams).latch is False


def test_qos_defaults_when_missing() -> None:
    params = offer_params()
    del params["qos"]
    assert DDSOffer.from_xmlrpc(params).qos == SubscribeQoSOptions()
    aparams = answer_params()
    del aparams["qos"]
    assert DDSAnswer.from_xmlrpc(aparams).qos == AdvertiseQoSOptions()


def test_is_guid() -> None:
    assert is_guid(GUID_R)
    for bad in (GUID_R.upper(), GUID_R[:-1], GUID_R + "0", GUID_R.replace("-", ""), " " + GUID_R,
                "", None, 1, b"01106fda-d45a-29f3-b1ee-b181000001c1", "g1106fda-d45a-29f3-b1ee-b181000001c1"):
        assert not is_guid(bad), bad


def test_guid_with_trailing_newline_is_not_a_guid() -> None:
    """``re.match`` with ``$`` also matches before a final newline: the GUID check must not pass it."""
    assert not is_guid(GUID_R + "\n")
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(reader=GUID_R + "\n"), "reader")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(writer=GUID_W + "\n"), "writer")


def expect_malformed(parse: Callable[[object], object], params: object, field: str) -> MalformedNegotiationError:
    with pytest.raises(MalformedNegotiationError) as info:
        parse(params)
    assert info.value.field == field, (info.value.field, str(info.value))
    assert str(info.value).startswith(f"{field}: ")
    assert isinstance(info.value, ValueError)
    return info.value


@pytest.mark.parametrize("params", [None, [], "DDS", 1, ["domain", 0], (1, 2)])
def test_offer_not_a_struct(params: object) -> None:
    expect_malformed(DDSOffer.from_xmlrpc, params, "DDS offer")
    expect_malformed(DDSAnswer.from_xmlrpc, params, "DDS answer")


OFFER_STR_FIELDS = ["topic", "type", "md5", "reader", "participant", "graph"]
NOT_STRINGS: List[object] = [None, 1, 1.5, True, b"abc", ["a"], {"a": "b"}]


@pytest.mark.parametrize("key", OFFER_STR_FIELDS)
@pytest.mark.parametrize("value", NOT_STRINGS)
def test_offer_string_field_wrong_type(key: str, value: object) -> None:
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(**{key: value}), key)


@pytest.mark.parametrize("key", OFFER_STR_FIELDS + ["domain"])
def test_offer_missing_field(key: str) -> None:
    params = offer_params()
    del params[key]
    expect_malformed(DDSOffer.from_xmlrpc, params, key)


@pytest.mark.parametrize("key", ["writer", "participant"])
def test_answer_missing_field(key: str) -> None:
    params = answer_params()
    del params[key]
    expect_malformed(DDSAnswer.from_xmlrpc, params, key)


@pytest.mark.parametrize("key", ["writer", "participant", "node"])
@pytest.mark.parametrize("value", [1, 1.5, True, b"abc", ["a"], {"a": "b"}])
def test_answer_string_field_wrong_type(key: str, value: object) -> None:
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(**{key: value}), key)


@pytest.mark.parametrize("value", [True, False, 1.0, "0", None, [0], 2 ** 31, -(2 ** 31) - 1, 10 ** 100])
def test_offer_domain_invalid(value: object) -> None:
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(domain=value), "domain")


@pytest.mark.parametrize("value", [1, 0, "true", "", None, 1.0, [True]])
def test_offer_transient_local_must_be_bool(value: object) -> None:
    params = offer_params(transient_local=value)
    if value is None:
        params["transient_local"] = None
    expect_malformed(DDSOffer.from_xmlrpc, params, "transient_local")


@pytest.mark.parametrize("value", [1, 0, "true", None, 1.0])
def test_answer_latch_must_be_bool(value: object) -> None:
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(latch=value), "latch")


@pytest.mark.parametrize("key", OFFER_STR_FIELDS)
def test_offer_string_over_limit(key: str) -> None:
    err = expect_malformed(DDSOffer.from_xmlrpc, offer_params(**{key: "a" * (MAX_FIELD_CHARS + 1)}), key)
    assert str(MAX_FIELD_CHARS) in str(err)


@pytest.mark.parametrize("key", ["topic", "type", "md5", "graph"])
def test_offer_string_at_limit_accepted(key: str) -> None:
    DDSOffer.from_xmlrpc(offer_params(**{key: "a" * MAX_FIELD_CHARS}))


@pytest.mark.parametrize("key", ["writer", "participant", "node"])
def test_answer_string_over_limit(key: str) -> None:
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(**{key: "a" * (MAX_FIELD_CHARS + 1)}), key)


@pytest.mark.parametrize("key", OFFER_STR_FIELDS)
def test_offer_one_megabyte_string_raises_quickly_and_short(key: str) -> None:
    huge = "0" * 1_000_000
    start = time.thread_time()  # this thread's CPU: a loaded machine's preemption is not the parser's
    err = expect_malformed(DDSOffer.from_xmlrpc, offer_params(**{key: huge}), key)
    assert time.thread_time() - start < 0.25
    assert len(str(err)) < 500  # the error does not carry the megabyte


@pytest.mark.parametrize("key", ["writer", "participant", "node"])
def test_answer_one_megabyte_string_raises_quickly(key: str) -> None:
    start = time.thread_time()  # this thread's CPU: a loaded machine's preemption is not the parser's
    err = expect_malformed(DDSAnswer.from_xmlrpc, answer_params(**{key: "f" * 1_000_000}), key)
    assert time.thread_time() - start < 0.25
    assert len(str(err)) < 500


@pytest.mark.parametrize("bad", [GUID_R.upper(), GUID_R[:-1], "not-a-guid", "", GUID_R + " "])
def test_bad_guids(bad: str) -> None:
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(reader=bad), "reader")
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(participant=bad), "participant")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(writer=bad), "writer")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(participant=bad), "participant")


@pytest.mark.parametrize("qos", [[], "deadline", 1, None, True, {str(i): 0 for i in range(17)}])
def test_qos_not_a_struct(qos: object) -> None:
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos=qos), "qos")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(qos=qos), "qos")


def test_qos_unknown_key() -> None:
    err = expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos={"bogus": 1}), "qos")
    assert "bogus" in str(err)
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos={"deadline_cb": "print"}), "qos")
    # an Advertise key is not a Subscribe key and vice versa
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos={"msg_valid_period": 1.0}), "qos")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(qos={"deadline": 1.0}), "qos")
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(qos={7: 1.0}), "qos")


@pytest.mark.parametrize("qos", [
    {"deadline": -1.0}, {"deadline": 0.0}, {"deadline": "soon"}, {"deadline": True}, {"deadline": [1]},
    {"deadline": "nan"}, {"time_filter_duration": "inf"}, {"ordered_by_sending_timestamp": 1},
    {"using_best_effort_protocol": "yes"}, {"data_centric_update": True}, {"deadline": {"to_sec": 1}},
])
def test_offer_bad_qos_value(qos: Dict[str, Any]) -> None:
    err = expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos=qos), "qos")
    assert len(str(err)) <= 310


@pytest.mark.parametrize("qos", [
    {"transport_priority": "LOUDEST"}, {"transport_priority": 99}, {"transport_priority": None},
    {"transport_priority": [1]}, {"latency_budget": -0.1}, {"msg_valid_period": 0.0},
    {"msg_valid_period": "forever"}, {"using_best_effort_protocol": 0}, {"data_centric_update": True},
    {"transport_priority": "x" * 1_000_000},
])
def test_answer_bad_qos_value(qos: Dict[str, Any]) -> None:
    start = time.thread_time()  # this thread's CPU: a loaded machine's preemption is not the parser's
    err = expect_malformed(DDSAnswer.from_xmlrpc, answer_params(qos=qos), "qos")
    assert time.thread_time() - start < 0.25
    assert len(str(err)) <= 310


@pytest.mark.parametrize("key", ["deadline", "time_filter_duration"])
def test_offer_qos_string_over_limit_rejected(key: str) -> None:
    """A QoS value is a field of the offer too: a megabyte string there is refused like any other.

    (``"1" * 1_000_000`` parses as float ``inf``; without a length check it is silently accepted.)
    """
    start = time.thread_time()  # this thread's CPU: a loaded machine's preemption is not the parser's
    expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos={key: "1" * 1_000_000}), "qos")
    assert time.thread_time() - start < 0.25


@pytest.mark.parametrize("key", ["latency_budget", "msg_valid_period"])
def test_answer_qos_string_over_limit_rejected(key: str) -> None:
    expect_malformed(DDSAnswer.from_xmlrpc, answer_params(qos={key: "1" * 1_000_000}), "qos")


def test_error_chains_the_qos_error() -> None:
    err = expect_malformed(DDSOffer.from_xmlrpc, offer_params(qos={"deadline": -1}), "qos")
    assert err.__cause__ is not None
    assert "deadline" in err.problem


# ----------------------------------------------------------------------------------------------- decide


def facts(**changes: Any) -> PublicationFacts:
    base = PublicationFacts(topic="/chatter", dds_topic="rt/chatter", domain=0, type_name=TYPE, md5=MD5,
                            options=AdvertiseQoSOptions(), latch=False)
    return dataclasses.replace(base, **changes)


SUB = "/listener"


def assert_declined(verdict: Verdict, kind: str, *words: str) -> None:
    assert not verdict.accepted and not verdict, verdict
    assert verdict.kind == kind, verdict
    for word in ("/chatter", SUB) + words:
        assert word in verdict.reason, (word, verdict.reason)


def test_decide_accepts_matching_offer() -> None:
    verdict = decide(make_offer(), facts(), subscriber=SUB)
    assert verdict.accepted and bool(verdict)
    assert verdict.kind == "accepted"
    assert "/chatter" in verdict.reason and SUB in verdict.reason


def test_decide_dds_unavailable() -> None:
    assert_declined(decide(make_offer(), facts(domain=None), subscriber=SUB), "dds-unavailable", "TCPROS")


def test_decide_dds_unavailable_comes_first() -> None:
    # even an offer wrong in every other way is declined for the first reason
    offer = make_offer(domain=5, md5="0", type_name="x", topic="rt/other")
    assert decide(offer, facts(domain=None), subscriber=SUB).kind == "dds-unavailable"


def test_decide_domain() -> None:
    assert_declined(decide(make_offer(domain=7), facts(domain=3), subscriber=SUB), "domain", "7", "3",
                    "ROS_DOMAIN_ID")


def test_decide_md5() -> None:
    assert_declined(decide(make_offer(md5="abcdef0123"), facts(), subscriber=SUB), "md5", "abcdef0123", MD5)


def test_decide_md5_wildcard_accepted() -> None:
    assert decide(make_offer(md5="*"), facts(), subscriber=SUB).kind == "accepted"


def test_decide_type() -> None:
    assert_declined(decide(make_offer(type_name="std_msgs::msg::dds_::Int32_"), facts(), subscriber=SUB), "type",
                    "std_msgs::msg::dds_::Int32_", TYPE)


def test_decide_topic() -> None:
    assert_declined(decide(make_offer(topic="rt/other"), facts(), subscriber=SUB), "topic", "rt/other",
                    "rt/chatter")


def test_decide_qos_best_effort() -> None:
    verdict = decide(make_offer(), facts(options=AdvertiseQoSOptions(using_best_effort_protocol=True)),
                     subscriber=SUB)
    assert_declined(verdict, "qos:using_best_effort_protocol", "using_best_effort_protocol=True",
                    "using_best_effort_protocol=False", "TCPROS")
    # a best-effort subscriber takes a best-effort publisher
    offer = make_offer(qos=SubscribeQoSOptions(using_best_effort_protocol=True))
    assert decide(offer, facts(options=AdvertiseQoSOptions(using_best_effort_protocol=True)),
                  subscriber=SUB).accepted


def test_decide_transient_local_against_non_latched_publisher_declined() -> None:
    verdict = decide(make_offer(transient_local=True), facts(latch=False), subscriber=SUB)
    assert_declined(verdict, "qos:latch", "latch=False", "transient-local")


def test_decide_transient_local_against_latched_publisher_accepted() -> None:
    assert decide(make_offer(transient_local=True), facts(latch=True), subscriber=SUB).kind == "accepted"


def test_decide_volatile_against_latched_publisher_accepted() -> None:
    assert decide(make_offer(transient_local=False), facts(latch=True), subscriber=SUB).kind == "accepted"


def test_decide_pending_limit() -> None:
    assert decide(make_offer(), facts(pending=MAX_PENDING_DDS_OFFERS - 1), subscriber=SUB).accepted
    verdict = decide(make_offer(), facts(pending=MAX_PENDING_DDS_OFFERS), subscriber=SUB)
    assert_declined(verdict, "pending-limit", str(MAX_PENDING_DDS_OFFERS), "TCPROS")
    assert decide(make_offer(), facts(pending=10 * MAX_PENDING_DDS_OFFERS), subscriber=SUB).kind == "pending-limit"


def test_decide_pending_limit_after_compatibility() -> None:
    # an incompatible offer says why it is incompatible, not that the table is full
    verdict = decide(make_offer(domain=1), facts(pending=MAX_PENDING_DDS_OFFERS), subscriber=SUB)
    assert verdict.kind == "domain"


# ----------------------------------------------------------------------------------------------- choose


class Judge:
    """A judge_dds that records the offers it saw and answers with a fixed verdict."""

    def __init__(self, accept: bool = True) -> None:
        self.accept = accept
        self.seen: List[DDSOffer] = []
        self.answer = make_answer()

    def __call__(self, offer: DDSOffer) -> Tuple[Verdict, Optional[DDSAnswer]]:
        self.seen.append(offer)
        if self.accept:
            return Verdict(True, "accepted", "ok"), self.answer
        return Verdict(False, "domain", "declined for test"), None


def tcpros_only(name: str) -> bool:
    return name == TCPROS


def choose(protocols: object, judge: Optional[Judge], supports: Callable[[str], bool] = tcpros_only) -> Choice:
    return choose_protocol(protocols, negotiated={} if judge is None else {DDS: dds_transport(judge)},
                           supports=supports, subscriber=SUB, topic="/chatter")


DDS_ENTRY = make_offer().to_xmlrpc()
TCP_ENTRY: List[Any] = [TCPROS]


def test_choose_dds_first() -> None:
    judge = Judge()
    choice = choose([DDS_ENTRY, TCP_ENTRY], judge)
    assert choice.answer_for(DDS) == judge.answer and choice.entry is None and choice.declined == []
    assert judge.seen == [make_offer()]


def test_choose_tcpros_first_honoured() -> None:
    judge = Judge()
    choice = choose([TCP_ENTRY, DDS_ENTRY], judge)
    assert choice.entry == TCP_ENTRY and choice.answer_for(DDS) is None
    assert judge.seen == []  # never judged: the subscriber preferred TCPROS


def test_choose_declined_dds_falls_through_to_tcpros() -> None:
    judge = Judge(accept=False)
    choice = choose([DDS_ENTRY, TCP_ENTRY], judge)
    assert choice.answer_for(DDS) is None and choice.entry == TCP_ENTRY
    assert [v.kind for v in choice.declined] == ["domain"]


def test_choose_over_the_wire() -> None:
    judge = Judge()
    choice = choose(wire([DDS_ENTRY, TCP_ENTRY]), judge)
    assert choice.answer_for(DDS) is not None and judge.seen == [make_offer()]


def test_choose_accepted_verdict_without_answer_is_not_dds() -> None:
    def judge(offer: DDSOffer) -> Tuple[Verdict, Optional[DDSAnswer]]:
        return Verdict(True, "accepted", "ok"), None

    choice = choose_protocol([DDS_ENTRY, TCP_ENTRY], negotiated={DDS: dds_transport(judge)}, supports=tcpros_only,
                             subscriber=SUB,
                             topic="/chatter")
    assert choice.answer_for(DDS) is None and choice.entry == TCP_ENTRY


@pytest.mark.parametrize("protocols", [None, "TCPROS", {"TCPROS": 1}, ("TCPROS",), 5])
def test_choose_protocols_not_a_list(protocols: object) -> None:
    choice = choose(protocols, Judge())
    assert choice.answer_for(DDS) is None and choice.entry is None
    assert [v.kind for v in choice.declined] == ["malformed"]
    assert SUB in choice.declined[0].reason and "/chatter" in choice.declined[0].reason


def test_choose_skips_malformed_entries() -> None:
    judge = Judge()
    protocols: List[Any] = ["TCPROS", [], [1], [None, "x"], {"TCPROS": 1}, 3, [b"TCPROS"], TCP_ENTRY]
    choice = choose(protocols, judge)
    assert choice.entry == TCP_ENTRY
    assert [v.kind for v in choice.declined] == ["malformed"] * 7
    assert all(SUB in v.reason for v in choice.declined)


@pytest.mark.parametrize("entry,field", [
    ([DDS], "DDS offer"),
    ([DDS, "x"], "DDS offer"),
    ([DDS, offer_params(domain="0")], "domain"),
    ([DDS, offer_params(reader="nope")], "reader"),
    ([DDS, offer_params(qos={"bogus": 1})], "qos"),
    ([DDS, offer_params(topic="t" * 1_000_000)], "topic"),
])
def test_choose_malformed_dds_offer_falls_through(entry: List[Any], field: str) -> None:
    judge = Judge()
    choice = choose([entry, TCP_ENTRY], judge)
    assert choice.entry == TCP_ENTRY and choice.answer_for(DDS) is None
    assert [v.kind for v in choice.declined] == [f"malformed:{field}"]
    assert SUB in choice.declined[0].reason
    assert len(choice.declined[0].reason) < 1000
    assert judge.seen == []


def test_choose_thousand_entries_bounded() -> None:
    judge = Judge(accept=False)
    protocols: List[Any] = [DDS_ENTRY] * 500 + [[1]] * 500
    start = time.perf_counter()
    choice = choose(protocols, judge)
    assert time.perf_counter() - start < 0.5
    assert choice.answer_for(DDS) is None and choice.entry is None
    # the loop looks at a bounded prefix: neither judge calls nor verdicts grow with the list
    assert 0 < len(judge.seen) <= 16 and len(choice.declined) <= 16


def test_choose_thousand_malformed_entries_bounded() -> None:
    choice = choose([[]] * 1000 + [TCP_ENTRY], Judge())
    assert len(choice.declined) <= 16


def test_choose_without_judge_skips_dds_silently() -> None:
    choice = choose([DDS_ENTRY, TCP_ENTRY], None)
    assert choice.entry == TCP_ENTRY and choice.answer_for(DDS) is None and choice.declined == []
    # even a malformed DDS entry: a stock node would not look at it
    choice = choose([[DDS, "garbage"], TCP_ENTRY], None)
    assert choice.entry == TCP_ENTRY and choice.declined == []


def test_choose_nothing_supported() -> None:
    choice = choose([["UDPROS", "x"], ["SHM"]], Judge(), supports=lambda name: False)
    assert choice == Choice()
    choice = choose([], Judge())
    assert choice.answer_for(DDS) is None and choice.entry is None and choice.declined == []
    choice = choose([DDS_ENTRY], Judge(accept=False))
    assert choice.answer_for(DDS) is None and choice.entry is None and len(choice.declined) == 1


def test_choose_supports_other_protocols() -> None:
    seen: List[str] = []

    def supports(name: str) -> bool:
        seen.append(name)
        return name == "UDPROS"

    choice = choose([["XSHM"], ["UDPROS", 1], TCP_ENTRY], Judge(), supports=supports)
    assert choice.entry == ["UDPROS", 1] and seen == ["XSHM", "UDPROS"]


# -------------------------------------------------------------------------------------------- ratelimit


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Lines:
    def __init__(self) -> None:
        self.lines: List[str] = []

    def warning(self, msg: str, *args: Any) -> None:
        self.lines.append(msg % args)


def test_ratelimit_first_logged_repeats_counted_summary_after_interval() -> None:
    clock, out = FakeClock(), Lines()
    log = RateLimitedLog(out, interval=30.0, clock=clock)
    assert log.warning(("/a", "md5"), "first")
    assert out.lines == ["micros_rt: first"]
    for i in range(5):
        clock.now += 1.0
        assert not log.warning(("/a", "md5"), "again")
    assert len(out.lines) == 1 and log.suppressed_total == 5
    clock.now = 1000.0 + 30.0
    assert log.warning(("/a", "md5"), "later")
    assert len(out.lines) == 2
    assert out.lines[1].startswith("micros_rt: later (")
    assert "6 more like this in the last 30 s" in out.lines[1]
    # the count restarts after a summary
    clock.now += 1.0
    assert not log.warning(("/a", "md5"), "x")
    clock.now += 30.0
    assert log.warning(("/a", "md5"), "y")
    assert "2 more like this in the last 31 s" in out.lines[2]


def test_ratelimit_keys_are_independent() -> None:
    out = Lines()
    log = RateLimitedLog(out, clock=FakeClock())
    assert log.warning("a", "A")
    assert log.warning("b", "B")
    assert not log.warning("a", "A")
    assert out.lines == ["micros_rt: A", "micros_rt: B"]


def test_ratelimit_max_keys_bounds_memory() -> None:
    clock, out = FakeClock(), Lines()
    log = RateLimitedLog(out, max_keys=8, clock=clock)
    for i in range(10_000):
        log.warning(("/attacker", i), "invented")
        assert len(log._seen) <= 8
    # the oldest keys were forgotten: the first one is new again
    assert log.warning(("/attacker", 0), "invented")


def test_ratelimit_groups_bound_memory_and_lines() -> None:
    clock, out = FakeClock(), Lines()
    log = RateLimitedLog(out, max_keys=8, per_group=5, clock=clock, interval=30.0)
    for i in range(1000):
        log.warning((f"/n{i}", "malformed"), "m", group="malformed")
    assert len(out.lines) == 5
    assert log.suppressed_total == 995
    clock.now += 31.0
    out.lines.clear()
    # the next window: the group's next line reports what the cap held back
    assert log.warning(("/new", "malformed"), "m", group="malformed")
    assert out.lines == ["micros_rt: m (995 more like this from other callers were not logged)"]
    for i in range(1000):
        log.warning(("/x", i), "g", group=("g", i))
        assert len(log._groups) <= 8 and len(log._seen) <= 8


def test_ratelimit_2000_warnings_one_line(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("test_negotiation.ratelimit")
    log = RateLimitedLog(logger, interval=30.0)
    with caplog.at_level(logging.WARNING, logger="test_negotiation.ratelimit"):
        start = time.perf_counter()
        written = sum(log.warning(("/flooder", "malformed"), "topic /a: malformed offer") for _ in range(2000))
        elapsed = time.perf_counter() - start
    records = [r for r in caplog.records if r.name == "test_negotiation.ratelimit"]
    assert written == 1 and len(records) == 1
    assert records[0].getMessage() == "micros_rt: topic /a: malformed offer"
    assert records[0].levelno == logging.WARNING
    assert log.suppressed_total == 1999
    assert elapsed < 1.0


class _ToyAnswer:
    def __init__(self, segment: str) -> None:
        self.segment = segment

    def to_xmlrpc(self) -> List[Any]:
        return ["SHM", {"segment": self.segment}]


def _toy_shm(accept: bool, seen: List[Any]) -> OfferJudge:
    """A negotiated shared-memory transport as a new back end would register it: its offer's reader and
    its publication's judge; nothing in choose_protocol knows its name."""
    def parse(params: Any, source: str) -> Any:
        if not isinstance(params, dict) or "host" not in params:
            raise MalformedNegotiationError("host", f"{source}: SHM offer without a host")
        return params

    def judge(offer: Any) -> Tuple[Verdict, Any]:
        seen.append(offer)
        if accept and offer["host"] == "here":
            return Verdict(True, "accepted", "same host"), _ToyAnswer("/dev/shm/t")
        return Verdict(False, "host", "another host: no shared memory"), None

    return OfferJudge(parse=parse, judge=judge)


def test_a_registered_negotiated_transport_is_chosen_in_the_subscribers_order() -> None:
    seen: List[Any] = []
    judge = Judge()
    negotiated = {"SHM": _toy_shm(True, seen), DDS: dds_transport(judge)}
    offers = [["SHM", {"host": "here"}], DDS_ENTRY, TCP_ENTRY]
    choice = choose_protocol(offers, negotiated=negotiated, supports=tcpros_only, subscriber=SUB, topic="/t")
    assert choice.protocol == "SHM" and choice.answer.to_xmlrpc() == ["SHM", {"segment": "/dev/shm/t"}]
    assert choice.answer_for(DDS) is None and judge.seen == []
    # declined with a reason: the next protocol in the subscriber's order, DDS
    choice = choose_protocol([["SHM", {"host": "there"}], DDS_ENTRY], negotiated=negotiated, supports=tcpros_only,
                             subscriber=SUB, topic="/t")
    assert choice.protocol == DDS and choice.answer_for(DDS) is judge.answer
    assert [v.kind for v in choice.declined] == ["host"]
    # malformed: skipped with its field named; a publication without the transport skips it silently
    choice = choose_protocol([["SHM", 7], TCP_ENTRY], negotiated=negotiated, supports=tcpros_only, subscriber=SUB,
                             topic="/t")
    assert choice.entry == TCP_ENTRY and [v.kind for v in choice.declined] == ["malformed:host"]
    choice = choose_protocol([["SHM", {"host": "here"}], TCP_ENTRY], negotiated={}, supports=tcpros_only,
                             subscriber=SUB, topic="/t")
    assert choice.entry == TCP_ENTRY
