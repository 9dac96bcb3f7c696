"""How the ``micros-rt`` tools mark a relay's links (issue 21): the ``relay`` section of a node's
``microsRtInfo`` (added through :func:`micros_rt.core.introspection.register_section`) turned into "relayed
out as ..." / "relayed in from ..." in ``topic info`` and relay nodes, ``outside:`` pseudo-nodes and relay
edges in ``graph --dot``; nodes without the section print as before."""

from __future__ import annotations

import json
from typing import Any, Dict, List, Optional

import pytest

from micros_rt.cli._graphinfo import (MICROS_RT, STOCK, GraphSnapshot, NodeReport, build_links, pacing_of,
                                      relay_marking)
from micros_rt.cli.graph import RELAY_COLOUR, to_dot
from micros_rt.cli.topic import format_info
from micros_rt.core import introspection
from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority

T = "/chatter"
OUTSIDE = "/robot_a/chatter"
A_URI = {"/talker": "http://127.0.0.1:1001/", "/relay_robot_a_high": "http://127.0.0.1:1002/",
         "/plain": "http://127.0.0.1:1003/"}


def export(max_rate: Optional[float] = 5.0) -> Dict[str, Any]:
    return {"topic": T, "outside": OUTSIDE, "protocol": "DDS", "process": "/relay_robot_a_high",
            "qos": AdvertiseQoSOptions(transport_priority=TransportPriority.HIGH).to_dict(), "max_rate": max_rate,
            "queue_size": 10, "latch": False,
            "counters": {"received": 100, "sent": 10, "rate_capped": 90, "looped": 0, "no_reader": 0,
                         "superseded": 0, "dropped_queue_full": 0}}


def relay_node(name: str, uri: str, bus: List[List[Any]], section: Dict[str, Any], *,
               pubs: Optional[List[Dict[str, Any]]] = None, subs: Optional[List[Dict[str, Any]]] = None) -> NodeReport:
    return NodeReport(name, uri, MICROS_RT, bus=bus,
                      info={"publications": pubs or [], "subscriptions": subs or [], "relay": section})


def graph_a() -> Dict[str, NodeReport]:
    """Robot A: a stock talker of /chatter, a stock listener, and a relay child exporting /chatter."""
    talker = NodeReport("/talker", A_URI["/talker"], STOCK,
                        bus=[[1, "/relay_robot_a_high", "o", "TCPROS", T, True, ""], [2, "/plain", "o", "TCPROS", T, True, ""]])
    sub = {"topic": T, "type": "std_msgs/String", "queue_size": 10,
           "qos": SubscribeQoSOptions(ordered_by_sending_timestamp=False).to_dict(), "hints": ["DDS", "TCPROS"],
           "dds_reader": True}
    child = relay_node("/relay_robot_a_high", A_URI["/relay_robot_a_high"],
                       [[1, A_URI["/talker"], "i", "TCPROS", T, True, ""]],
                       {"graph": "robot_a", "node": "/relay_robot_a_high", "parent": "/relay_robot_a", "children": [],
                        "exports": [export()], "imports": []}, subs=[sub])
    plain = NodeReport("/plain", A_URI["/plain"], STOCK, bus=[[1, A_URI["/talker"], "i", "TCPROS", T, True, ""]])
    return {n.name: n for n in (talker, child, plain)}


def snapshot_of(nodes: Dict[str, NodeReport], topic: str, pubs: List[str], subs: List[str]) -> GraphSnapshot:
    return GraphSnapshot("http://127.0.0.1:11311/", {topic: "std_msgs/String"}, {topic: pubs}, {topic: subs}, nodes,
                         build_links(topic, pubs, subs, nodes))


def graph_b() -> GraphSnapshot:
    """Robot B: the relay publishing the import /robot_a/chatter, a stock listener of it."""
    pub = {"topic": OUTSIDE, "type": "std_msgs/String", "latch": False, "queue_size": 10,
           "qos": AdvertiseQoSOptions().to_dict(), "dds_topic": "rt/robot_a/chatter", "links": [], "verdicts": {}}
    relay_b = relay_node("/relay_robot_b", "http://127.0.0.1:2001/", [[1, "/listener", "o", "TCPROS", OUTSIDE, True, ""]],
                         {"graph": "robot_b", "node": "/relay_robot_b", "parent": None, "children": [],
                          "exports": [], "imports": [{"outside": OUTSIDE, "local": OUTSIDE, "origin": "robot_a",
                                                      "exporters": [], "protocol": "DDS", "qos": None,
                                                      "counters": {"received": 7, "published": 7, "lost": 2}}]},
                         pubs=[pub])
    listener = NodeReport("/listener", "http://127.0.0.1:2002/", STOCK,
                          bus=[[1, "http://127.0.0.1:2001/", "i", "TCPROS", OUTSIDE, True, ""]])
    return snapshot_of({n.name: n for n in (relay_b, listener)}, OUTSIDE, ["/relay_robot_b"], ["/listener"])


def test_a_relay_export_is_marked_on_its_subscription_only() -> None:
    nodes = graph_a()
    child = nodes["/relay_robot_a_high"]
    out = relay_marking(child, T, publisher=False)
    assert out is not None
    assert out["description"] == ("relayed out as /robot_a/chatter (DDS, HIGH, reliable, max_rate 5 Hz) by relay "
                                  "node /relay_robot_a_high (a process of relay /relay_robot_a); sent 10 of 100 "
                                  "received (rate capped 90)")
    assert (out["relay"], out["relay_node"], out["transport_priority"]) == ("/relay_robot_a", "/relay_robot_a_high",
                                                                            "HIGH")
    assert relay_marking(child, T, publisher=True) is None          # it does not publish /chatter
    assert relay_marking(child, "/other", publisher=False) is None  # not an exported topic
    assert relay_marking(nodes["/plain"], T, publisher=False) is None
    no_cap = relay_node("/r", "http://x/", [], {"graph": "g", "exports": [export(None)]})
    marking = relay_marking(no_cap, T, publisher=False)
    assert marking is not None and "(DDS, HIGH, reliable, no max_rate)" in marking["description"]
    broken = relay_node("/r", "http://x/", [], {"error": "RuntimeError: boom"})
    assert broken.relay() is None and relay_marking(broken, T, publisher=False) is None


def test_a_relay_import_is_marked_on_its_publication() -> None:
    snap = graph_b()
    ep = snap.endpoint("/relay_robot_b", OUTSIDE, publisher=True)
    assert ep["relay"]["description"] == ("relayed in from graph robot_a (outside topic /robot_a/chatter, no "
                                          "exporting relay seen now) by relay node /relay_robot_b; published 7 of 7 "
                                          "received (lost 2)")
    assert "relay" not in snap.endpoint("/listener", OUTSIDE, publisher=False)
    (link,) = snap.links
    assert [m["direction"] for m in link.to_dict()["relayed"]] == ["in"]


def test_subscribers_reading_the_exporter_straight_are_counted_on_the_import() -> None:
    relay_b = relay_node("/relay_robot_b", "http://127.0.0.1:2001/", [],
                         {"graph": "robot_b", "imports": [{"outside": OUTSIDE, "local": OUTSIDE, "origin": "robot_a",
                                                           "exporters": ["/relay_robot_a"], "straight": 2,
                                                           "counters": {"received": 3, "published": 3}}]})
    marking = relay_marking(relay_b, OUTSIDE, publisher=True)
    assert marking is not None and marking["straight"] == 2
    assert marking["description"].endswith("published 3 of 3 received; 2 micros_rt subscribers read it straight "
                                           "from graph robot_a's relay")


def test_an_import_s_drops_are_said_in_words_the_enforcers_counters_from_the_catalogue() -> None:
    counters = {"received": 20, "published": 9, "dropped_queue_full": 1, "dropped_expired": 2, "deadline_missed": 3,
                "dropped_filtered": 4, "dropped_out_of_order": 5, "refused": 6, "bad_input": 7, "lost": 8}
    relay_b = relay_node("/relay_robot_b", "http://127.0.0.1:2001/", [],
                         {"graph": "robot_b", "imports": [{"outside": OUTSIDE, "local": OUTSIDE, "origin": "robot_a",
                                                           "counters": counters}]})
    marking = relay_marking(relay_b, OUTSIDE, publisher=True)
    assert marking is not None
    assert marking["description"].endswith(
        "published 9 of 20 received (queue full 1, expired 2, deadline missed 3, filtered 4, out of order 5, "
        "refused 6, bad input 7, lost 8)")


def test_links_between_ordinary_nodes_keep_their_json_and_text() -> None:
    snap = snapshot_of(graph_a(), T, ["/talker"], ["/plain", "/relay_robot_a_high"])
    links = {link.subscriber: link.to_dict() for link in snap.links}
    assert "relayed" not in links["/plain"]
    assert [m["outside"] for m in links["/relay_robot_a_high"]["relayed"]] == [OUTSIDE]
    data = {"topic": T, "type": "std_msgs/String",
            "publishers": [snap.endpoint("/talker", T, publisher=True)],
            "subscribers": [snap.endpoint(n, T, publisher=False) for n in ("/plain", "/relay_robot_a_high")],
            "links": list(links.values())}
    json.dumps(data)   # --json prints it
    lines = format_info(data).splitlines()
    at = lines.index(" * /talker -> /plain: TCPROS, transport priority n/a (stock publisher)")
    assert lines[at + 1:at + 5] == ["     publisher QoS:  stock ROS endpoint (TCPROS only, no micros_rt QoS)",
                                    "     subscriber QoS: stock ROS endpoint (TCPROS only, no micros_rt QoS)",
                                    "     why TCPROS: the publisher is a stock ROS node (TCPROS only)",
                                    " * /talker -> /relay_robot_a_high: TCPROS, transport priority n/a (stock publisher)"]
    assert lines[at + 8].strip().startswith("relayed out as /robot_a/chatter (DDS, HIGH")
    assert not lines[at + 8].strip().endswith("(rate capped 90)")   # the link gives the summary, no counters
    plain = next(i for i, line in enumerate(lines) if line.startswith(" * /plain ("))
    assert lines[plain + 1].startswith(" * /relay_robot_a_high (")
    assert lines[plain + 2].strip().endswith("sent 10 of 100 received (rate capped 90)")


def test_dot_draws_relays_and_their_outside_topics() -> None:
    dot_a = to_dot(snapshot_of(graph_a(), T, ["/talker"], ["/plain", "/relay_robot_a_high"]))
    assert ('"n:/relay_robot_a_high" [label="/relay_robot_a_high\\nrelay, graph robot_a\\nprocess of /relay_robot_a", '
            'shape=hexagon') in dot_a
    assert (f'"n:/relay_robot_a_high" -> "o:{OUTSIDE}" [label="relay out\\nDDS HIGH\\nmax_rate 5 Hz", '
            f'color="{RELAY_COLOUR}"') in dot_a
    assert f'"t:{T}" -> "n:/relay_robot_a_high" [label="TCPROS from /talker\\nreliable\\nrelayed out as {OUTSIDE}"' \
        in dot_a
    assert f'"t:{T}" -> "n:/plain" [label="TCPROS from /talker", ' in dot_a
    assert "relay (between graphs)" in dot_a
    dot_b = to_dot(graph_b())
    assert f'"o:{OUTSIDE}" [label="outside: {OUTSIDE}\\nfrom graph robot_a"' in dot_b
    assert f'"o:{OUTSIDE}" -> "n:/relay_robot_b" [label="relay in\\nfrom graph robot_a\\nas {OUTSIDE}"' in dot_b
    assert f'"n:/relay_robot_b" -> "t:{OUTSIDE}" [label="reliable, NORMAL\\nrelayed in from graph robot_a"' in dot_b
    plain_only = {n: r for n, r in graph_a().items() if n != "/relay_robot_a_high"}
    dot = to_dot(snapshot_of(plain_only, T, ["/talker"], ["/plain"]))
    assert "relay" not in dot and "hexagon" not in dot and '"o:' not in dot


def test_register_section_adds_to_the_answer_and_guards_the_core(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(introspection, "_sections", {})
    introspection.register_section("relay", lambda: {"graph": "robot_a"})

    def broken() -> Dict[str, Any]:
        raise RuntimeError("closing")

    introspection.register_section("other", broken)
    assert introspection._extra_sections() == {"relay": {"graph": "robot_a"},
                                               "other": {"error": "RuntimeError: closing"}}
    for bad in ("publications", "node", ""):
        with pytest.raises(ValueError, match="one of the answer's own keys"):
            introspection.register_section(bad, lambda: {})
    introspection.unregister_section("other")
    introspection.unregister_section("never_registered")
    assert list(introspection._extra_sections()) == ["relay"]


def test_a_paced_publisher_says_so_under_its_endpoint_only() -> None:
    """A micros_rt publisher whose profile's link paces its TCPROS connection of /image (its microsRtInfo
    ``links``): topic info says so under that publisher; a topic it does not pace gets no such line."""
    pub = {"topic": "/image", "type": "std_msgs/String", "latch": False, "queue_size": 2,
           "qos": AdvertiseQoSOptions(transport_priority=TransportPriority.LOW).to_dict(), "dds_topic": "rt/image",
           "links": [], "verdicts": {}}
    camera = NodeReport("/camera", "http://10.0.0.1:1001/", MICROS_RT,
                        bus=[[1, "/viewer", "o", "TCPROS", "/image", True, ""]],
                        info={"publications": [pub], "subscriptions": [], "links": [
                            {"link": "radio", "describe": "link radio (...)", "connections": [
                                {"topic": "/image", "peer": "10.0.0.2", "rate_bps": 36e6, "used_bps": 35.99e6}]}]})
    viewer = NodeReport("/viewer", "http://10.0.0.2:1002/", STOCK,
                        bus=[[1, "http://10.0.0.1:1001/", "i", "TCPROS", "/image", True, ""]])
    snap = snapshot_of({"/camera": camera, "/viewer": viewer}, "/image", ["/camera"], ["/viewer"])
    ep = snap.endpoint("/camera", "/image", publisher=True)
    assert ep["paced"]["connections"][0]["link"] == "radio"
    data = {"topic": "/image", "type": "std_msgs/String", "publishers": [ep],
            "subscribers": [snap.endpoint("/viewer", "/image", publisher=False)],
            "links": [link.to_dict() for link in snap.links]}
    json.dumps(data)
    lines = format_info(data).splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith(" * /camera ("))
    assert lines[at + 1] == "     paced on link radio: TCPROS to 10.0.0.2 at 36 Mbit/s (used 36)", lines[at + 1]
    assert pacing_of(camera, "/other") is None and "paced" not in snap.endpoint("/viewer", "/image", publisher=False)
