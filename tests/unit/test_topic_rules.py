"""The one per-topic rule matcher (micros_rt/qos/topic_rules.py), used by QoS profiles and the MQTT back end."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from micros_rt import ProfileError, QoSProfile, TransportPriority
from micros_rt.transports.mqtt.backend import parse_mqtt_section
from micros_rt.qos.topic_rules import TopicPattern, best_match


def rules(*keys: str) -> list[tuple[TopicPattern, str]]:
    return [(TopicPattern.parse(k), k) for k in keys]


@pytest.mark.parametrize("topic, expected", [
    ("/cam/image", "/cam/image"),          # exact beats every pattern, wherever it stands
    ("/cam/info", "/cam/i*"),              # the longest pattern
    ("/cam/x", "^/cam/.$"),                # equally long: the first in the file
    ("/odom", None),
])
def test_exact_then_longest_then_first(topic: str, expected: str | None) -> None:
    assert best_match(rules("/cam/*", "^/cam/.$", "/cam/?", "/cam/i*", "/cam/image"), topic) == expected


def test_a_regex_matches_the_whole_name_and_a_glob_star_crosses_slashes() -> None:
    assert TopicPattern.parse("^/a/[0-9]+$").matches("/a/12") and not TopicPattern.parse("^/a/[0-9]+$").matches("/a/12x")
    assert TopicPattern.parse("/robot/*").matches("/robot/arm/joint")
    with pytest.raises(re.error):
        TopicPattern.parse("^/a/($")


def test_profiles_and_mqtt_rules_pick_the_same_rule(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text("publishers:\n"
                    "  /cam/*: {transport_priority: LOW}\n"
                    "  ^/cam/i.*$: {transport_priority: HIGH}\n"
                    "  /cam/image: {transport_priority: EXTREMELY_HIGH}\n")
    profile = QoSProfile.load(str(path))
    mqtt = parse_mqtt_section({"broker": {"host": "localhost"},
                               "topics": {"/cam/*": {"mqtt_topic": "low"}, "^/cam/i.*$": {"mqtt_topic": "high"},
                                          "/cam/image": {"mqtt_topic": "exact"}}}, source="p.yaml")
    for topic, prio, mqtt_topic in (("/cam/image", TransportPriority.EXTREMELY_HIGH, "exact"),
                                    ("/cam/info", TransportPriority.HIGH, "high"),
                                    ("/cam/depth", TransportPriority.LOW, "low")):
        options = profile.advertise_options(topic)
        rule = mqtt.rule_for(topic, "out")
        assert options is not None and options.transport_priority == prio
        assert rule is not None and rule.mqtt_topic == mqtt_topic


def test_a_profile_with_a_broken_regex_key_is_refused_with_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("subscribers:\n  ^/a/($: {deadline: 1.0}\n")
    with pytest.raises(ProfileError, match=r"bad.yaml:2: subscribers: key '\^/a/\(\$' is not a valid regular"):
        QoSProfile.load(str(path))
