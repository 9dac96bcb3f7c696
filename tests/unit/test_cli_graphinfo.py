"""Unit tests of the micros-rt tools' pure pieces: joining getBusInfo and microsRtInfo answers into links
(protocol, QoS, why not DDS), QoS in words, topic-name resolution, the verdict memory, the text forms."""

from __future__ import annotations

import collections
from typing import Any, Dict, List, Optional

import pytest

from micros_rt.negotiation import MAX_VERDICTS, remember_verdict
from micros_rt.cli import CommandError
from micros_rt.cli._args import ArgumentParser
from micros_rt.cli._graphinfo import (
    MICROS_RT,
    STOCK,
    UNREACHABLE,
    GraphSnapshot,
    NodeReport,
    build_links,
    describe_publisher_qos,
    describe_subscriber_qos,
    resolve_topic,
)
from micros_rt.cli.graph import PROTOCOL_COLOURS, to_dot
from micros_rt.cli.topic import format_info, format_latency
from micros_rt.negotiation import Verdict
from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority

T = "/chatter"
PUB_URI = {"/talker": "http://127.0.0.1:1001/", "/be_talker": "http://127.0.0.1:1002/",
           "/stock_talker": "http://127.0.0.1:1003/"}


def publication(*, links: List[Dict[str, Any]], verdicts: Optional[Dict[str, Any]] = None,
                qos: Optional[AdvertiseQoSOptions] = None, dds: bool = True) -> Dict[str, Any]:
    return {"topic": T, "type": "std_msgs/String", "latch": False, "queue_size": 10,
            "qos": (qos or AdvertiseQoSOptions()).to_dict(), "dds_topic": "rt/chatter" if dds else None,
            "links": links, "verdicts": verdicts or {}}


def subscription(*, hints: Optional[List[str]] = None, dds_reader: bool = True) -> Dict[str, Any]:
    return {"topic": T, "type": "std_msgs/String", "queue_size": 10,
            "qos": SubscribeQoSOptions(ordered_by_sending_timestamp=False).to_dict(),
            "hints": hints or ["DDS", "TCPROS"], "dds_reader": dds_reader}


def out(sub: str, proto: str) -> List[Any]:
    return [1, sub, "o", proto, T, True, "info"]


def inbound(pub: str, proto: str) -> List[Any]:
    return [2, PUB_URI[pub], "i", proto, T, True, "info"]


def mrt_node(name: str, uri: str, bus: List[List[Any]], *, pubs: Optional[List[Dict[str, Any]]] = None,
             subs: Optional[List[Dict[str, Any]]] = None) -> NodeReport:
    return NodeReport(name, uri, MICROS_RT, bus=bus, info={"publications": pubs or [], "subscriptions": subs or []})


def declined(sub: str) -> Dict[str, Any]:
    return {"accepted": False, "kind": "qos:using_best_effort_protocol",
            "reason": f"DDS QoS mismatch with subscriber {sub}, falling back to TCPROS: best effort vs reliable"}


def mixed_graph() -> Dict[str, NodeReport]:
    talker = mrt_node("/talker", PUB_URI["/talker"], [out("/listener", "DDS"), out("/stock_listener", "TCPROS")],
                      pubs=[publication(links=[{"subscriber": "/listener", "protocol": "DDS", "matched": True}],
                                        verdicts={"/listener": {"accepted": True, "kind": "accepted",
                                                                "reason": "ok"}},
                                        qos=AdvertiseQoSOptions(transport_priority=TransportPriority.HIGH))])
    be = mrt_node("/be_talker", PUB_URI["/be_talker"], [out("/listener", "TCPROS")],
                  pubs=[publication(links=[], verdicts={"/listener": declined("/listener")},
                                    qos=AdvertiseQoSOptions(using_best_effort_protocol=True))])
    listener = mrt_node("/listener", "http://127.0.0.1:2001/",
                        [inbound("/talker", "DDS"), inbound("/be_talker", "TCPROS")], subs=[subscription()])
    stock = NodeReport("/stock_listener", "http://127.0.0.1:2002/", STOCK, bus=[inbound("/talker", "TCPROS")])
    return {n.name: n for n in (talker, be, listener, stock)}


def links_by_pair(nodes: Dict[str, NodeReport], pubs: List[str], subs: List[str]) -> Dict[Any, Any]:
    return {(link.publisher, link.subscriber): link for link in build_links(T, pubs, subs, nodes)}


def test_links_of_a_mixed_graph_name_protocol_qos_priority_and_the_declined_reason() -> None:
    links = links_by_pair(mixed_graph(), ["/talker", "/be_talker"], ["/listener", "/stock_listener"])
    assert set(links) == {("/talker", "/listener"), ("/talker", "/stock_listener"), ("/be_talker", "/listener")}
    dds = links[("/talker", "/listener")]
    assert (dds.protocol, dds.transport_priority, dds.matched, dds.reason) == ("DDS", "HIGH", True, None)
    assert dds.publisher_qos is not None and dds.publisher_qos["queue_size"] == 10
    assert dds.subscriber_qos is not None and dds.subscriber_qos["hints"] == ["DDS", "TCPROS"]
    stock = links[("/talker", "/stock_listener")]
    assert (stock.protocol, stock.subscriber_kind, stock.subscriber_qos) == ("TCPROS", STOCK, None)
    assert stock.reason is not None and "subscriber is a stock ROS node" in stock.reason
    refused = links[("/be_talker", "/listener")]
    assert (refused.protocol, refused.verdict) == ("TCPROS", "qos:using_best_effort_protocol")
    assert refused.reason is not None and "falling back to TCPROS" in refused.reason


def test_a_publisher_that_does_not_answer_is_seen_from_its_subscribers() -> None:
    nodes = mixed_graph()
    nodes["/talker"] = NodeReport("/talker", PUB_URI["/talker"], UNREACHABLE)
    links = links_by_pair(nodes, ["/talker", "/be_talker"], ["/listener", "/stock_listener"])
    assert {k: v.protocol for k, v in links.items()} == {("/talker", "/listener"): "DDS",
                                                         ("/talker", "/stock_listener"): "TCPROS",
                                                         ("/be_talker", "/listener"): "TCPROS"}
    assert links[("/talker", "/listener")].publisher_kind == UNREACHABLE


def test_a_stock_publisher_is_tcpros_with_no_priority() -> None:
    stock = NodeReport("/stock_talker", PUB_URI["/stock_talker"], STOCK, bus=[out("/listener", "TCPROS")])
    listener = mrt_node("/listener", "http://127.0.0.1:2001/", [], subs=[subscription()])
    link = build_links(T, ["/stock_talker"], ["/listener"], {"/stock_talker": stock, "/listener": listener})[0]
    assert (link.protocol, link.transport_priority, link.publisher_qos) == ("TCPROS", None, None)
    assert link.reason is not None and "publisher is a stock ROS node" in link.reason


@pytest.mark.parametrize("hints,dds_reader,dds,expected", [
    (["TCPROS"], True, True, "allow only TCPROS"),
    (["TCPROS", "DDS"], True, True, "prefer TCPROS"),
    (["DDS", "TCPROS"], False, True, "unavailable in the subscriber"),
    (["DDS", "TCPROS"], True, False, "unavailable in the publisher"),
    (["DDS", "TCPROS"], True, True, "no DDS offer"),
])
def test_why_tcpros_between_micros_rt_nodes_without_a_verdict(hints: List[str], dds_reader: bool, dds: bool,
                                                              expected: str) -> None:
    pub = mrt_node("/talker", PUB_URI["/talker"], [out("/listener", "TCPROS")], pubs=[publication(links=[], dds=dds)])
    sub = mrt_node("/listener", "http://127.0.0.1:2001/", [], subs=[subscription(hints=hints, dds_reader=dds_reader)])
    link = build_links(T, ["/talker"], ["/listener"], {"/talker": pub, "/listener": sub})[0]
    assert link.reason is not None and expected in link.reason
    assert link.verdict is None


def test_qos_in_words() -> None:
    pub = dict(AdvertiseQoSOptions(transport_priority=TransportPriority.HIGH, latency_budget=0.005, msg_valid_period=2.0,
                                   using_best_effort_protocol=True).to_dict(), queue_size=None, latch=True)
    assert describe_publisher_qos(pub) == ("best effort, priority HIGH, latency budget 5 ms, valid for 2 s, latched, "
                                           "lossless (queue_size None)")
    assert describe_publisher_qos(AdvertiseQoSOptions().to_dict()) == "reliable, priority NORMAL"
    sub = dict(SubscribeQoSOptions(deadline=0.5, time_filter_duration=1.0).to_dict(), queue_size=5,
               hints=["TCPROS"])
    assert describe_subscriber_qos(sub) == ("reliable, deadline 500 ms, time filter 1 s, by source time, queue 5, "
                                            "hints TCPROS")


def test_topic_names_resolve_like_rostopic() -> None:
    assert resolve_topic("/a/b", {}) == "/a/b"
    assert resolve_topic("chatter", {}) == "/chatter"
    assert resolve_topic("chatter", {"ROS_NAMESPACE": "/robot1"}) == "/robot1/chatter"
    with pytest.raises(CommandError):
        resolve_topic("two words", {})


def test_verdict_memory_keeps_the_last_per_subscriber_and_is_bounded() -> None:
    table: "collections.OrderedDict[str, Verdict]" = collections.OrderedDict()
    remember_verdict(table, "/a", Verdict(False, "qos:x", "no"))
    remember_verdict(table, "/a", Verdict(True, "accepted", "yes"))
    assert table["/a"].accepted
    for i in range(MAX_VERDICTS + 10):
        remember_verdict(table, f"/n{i}", Verdict(False, "domain", "other domain"))
    assert len(table) == MAX_VERDICTS and "/a" not in table


def snapshot_of(nodes: Dict[str, NodeReport]) -> GraphSnapshot:
    pubs = {T: ["/talker", "/be_talker"], "/rosout": ["/talker"]}
    subs = {T: ["/listener", "/stock_listener"], "/rosout": ["/rosout"]}
    return GraphSnapshot("http://127.0.0.1:11311/", {T: "std_msgs/String"}, pubs, subs, nodes,
                         build_links(T, pubs[T], subs[T], nodes))


def test_dot_colours_links_by_protocol_and_hides_rosout() -> None:
    dot = to_dot(snapshot_of(mixed_graph()))
    assert '"t:/chatter" -> "n:/listener" [label="DDS from /talker' in dot
    assert f'color="{PROTOCOL_COLOURS["DDS"]}"' in dot and f'color="{PROTOCOL_COLOURS["TCPROS"]}"' in dot
    assert "DDS declined: qos:using_best_effort_protocol" in dot
    assert '"n:/talker" -> "t:/chatter" [label="reliable, HIGH"' in dot
    assert "/rosout" not in dot
    assert '"t:/rosout"' in to_dot(snapshot_of(mixed_graph()), include_all=True)


def test_info_text_names_each_link_and_the_declined_reason() -> None:
    snap = snapshot_of(mixed_graph())
    data = {"topic": T, "type": "std_msgs/String",
            "publishers": [snap.endpoint(n, T, publisher=True) for n in ("/be_talker", "/talker")],
            "subscribers": [snap.endpoint(n, T, publisher=False) for n in ("/listener", "/stock_listener")],
            "links": [link.to_dict() for link in snap.links]}
    text = format_info(data)
    assert " * /talker -> /listener: DDS, transport priority HIGH" in text
    assert " * /be_talker -> /listener: TCPROS, transport priority NORMAL" in text
    assert "DDS declined: DDS QoS mismatch with subscriber /listener" in text
    assert "[stock] stock ROS endpoint" in text


def test_latency_report_text() -> None:
    report = {"topic": T, "type": "std_msgs/String", "messages": 100, "rate_hz": 50.0,
              "transports": {"http://h:1/": "DDS"}, "timestamps": "DDS source timestamps",
              "latency_ms": {"count": 100, "mean": 0.5, "p50": 0.4, "p99": 1.5, "max": 2.0},
              "drops": {"queue_full": 0, "expired": 1, "filtered": 0, "malformed": 0, "total": 1},
              "deadline_misses": 2, "budget_misses": 3, "budget_checked": 100}
    text = format_latency(report)
    assert "p50 0.400 ms, p99 1.500 ms, max 2.000 ms" in text
    assert "drops:     1 (queue full 0, expired 1" in text
    assert "deadline misses: 2, latency budget misses: 3 of 100 checked" in text


def test_argument_errors_are_one_line_with_the_usage() -> None:
    parser = ArgumentParser(prog="micros-rt topic info", usage="%(prog)s [--json] /topic")
    parser.add_argument("topic")
    with pytest.raises(CommandError) as info:
        parser.parse_args([])
    assert info.value.code == 2
    assert "\n" not in str(info.value) and "usage: micros-rt topic info [--json] /topic" in str(info.value)
