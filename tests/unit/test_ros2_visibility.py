"""The ROS 2 visibility switch (profile ``ros2:``, ``MICROS_RT_ROS2``) and the lazy DDS offer it brings."""

from __future__ import annotations

import pytest

from micros_rt import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.transports.dds.process import ros2_mode, ros2_visible
from micros_rt.exceptions import ProfileError
from micros_rt.negotiation import PublicationFacts
from micros_rt.transports.dds.offer import DDSOffer, DDSOpenFirst, decide
from micros_rt.qos import QoSProfile


def test_profile_ros2_switch() -> None:
    assert QoSProfile.from_string("ros2: false").ros2 is False
    assert QoSProfile.from_string("ros2: true").ros2 is True
    assert QoSProfile.from_string("publishers: {}").ros2 is None
    with pytest.raises(ProfileError, match=r"ros2: expected true .* or false"):
        QoSProfile.from_string("ros2: sometimes", source="p.yaml")


@pytest.mark.parametrize("env,profile,want", [
    (None, None, "auto"), ("auto", QoSProfile.from_string("ros2: true"), "auto"),
    ("off", None, "off"), ("0", None, "off"), ("false", QoSProfile.from_string("ros2: true"), "off"),
    ("on", QoSProfile.from_string("ros2: false"), "on"),
    (None, QoSProfile.from_string("ros2: false"), "off"), (None, QoSProfile.from_string("ros2: true"), "on"),
    ("sometimes", None, "auto"),
])
def test_environment_wins_over_profile(monkeypatch: pytest.MonkeyPatch, env: str | None,
                                       profile: QoSProfile | None, want: str) -> None:
    if env is None:
        monkeypatch.delenv("MICROS_RT_ROS2", raising=False)
    else:
        monkeypatch.setenv("MICROS_RT_ROS2", env)
    assert ros2_mode(profile) == want
    # auto: visible once the host's watcher saw ROS 2 (this process has seen nothing)
    assert ros2_visible(profile) is (want == "on")


def test_lazy_offer_round_trip_and_open_first_answer() -> None:
    offer = DDSOffer(domain=7, topic="", type_name="", md5="992ce8a1687cec8c8bd883ec73ca41d1",
                     qos=SubscribeQoSOptions(), reader="", participant="", graph="g", lazy=True)
    entry = offer.to_xmlrpc()
    assert "reader" not in entry[1] and DDSOffer.from_xmlrpc(entry[1]) == offer
    assert DDSOpenFirst.is_one(DDSOpenFirst().to_xmlrpc())
    assert not DDSOpenFirst.is_one(["DDS", {"writer": "x"}]) and not DDSOpenFirst.is_one(["TCPROS"])


def test_a_lazy_offer_is_judged_on_domain_type_and_qos_like_a_full_one() -> None:
    facts = PublicationFacts("/c", "rt/c", 7, "std_msgs::msg::dds_::String_", "992ce8a1687cec8c8bd883ec73ca41d1",
                             AdvertiseQoSOptions(using_best_effort_protocol=True), latch=False)
    import dataclasses

    lazy = DDSOffer(domain=8, topic="", type_name="", md5=facts.md5, qos=SubscribeQoSOptions(), reader="",
                    participant="", graph="g", lazy=True)
    full = dataclasses.replace(lazy, topic=facts.dds_topic, type_name=facts.type_name)
    assert decide(full, facts, subscriber="/s").kind == "domain"
    full = dataclasses.replace(full, domain=7)
    assert decide(full, facts, subscriber="/s").kind == "qos:using_best_effort_protocol"
