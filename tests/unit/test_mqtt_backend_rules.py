"""The profile's 'mqtt' section: rules by exact name, glob or ^regex$, their validation and precedence."""

from __future__ import annotations

from typing import Any

import pytest

from micros_rt import ProfileError, QoSProfile
from micros_rt.transports.mqtt.backend import parse_mqtt_section

SECTION = {
    "broker": {"host": "127.0.0.1", "port": 1884},
    "topics": {
        "/cam/*": {"codec": "json"},
        "^/fleet/robot[0-9]+/cmd$": {"qos": 2, "direction": "in"},
        "/cam/front": {"mqtt_topic": "r1/{ros_topic}", "retained": True},
    },
}


def test_rules_precedence_and_names() -> None:
    s = parse_mqtt_section(SECTION, source="p.yaml")
    front = s.rule_for("/cam/front", "out")
    assert front is not None and front.key == "/cam/front" and front.mqtt_name("/cam/front") == "r1/cam/front"
    back = s.rule_for("/cam/back", "out")
    assert back is not None and back.codec == "json" and back.mqtt_name("/cam/back") == "cam/back"
    assert s.rule_for("/fleet/robot7/cmd", "out") is None                 # direction: in
    cmd = s.rule_for("/fleet/robot7/cmd", "in")
    assert cmd is not None and cmd.qos == 2
    assert s.rule_for("/fleet/robotX/cmd", "in") is None
    assert s.params.broker.port == 1884


@pytest.mark.parametrize("section, words", [
    ({"topics": {"chatter": {}}}, "must be a resolved ROS name"),
    ({"topics": {"/a": {"codec": "xml"}}}, "codec' is 'xml'"),
    ({"topics": {"/a": {"direction": "up"}}}, "direction' is 'up'"),
    ({"topics": {"/a": {"qos": 3}}}, "qos' is 3"),
    ({"topics": {"/a": {"mqtt_topic": "a/#"}}}, "without wildcards"),
    ({"topics": {"^([$": {}}}, "regular expression"),
    ({"brokr": {}}, "unknown parameter(s) 'brokr'"),
    ({"topics": {"/a": {"prio": 1}}}, "unknown parameter(s) 'prio'"),
])
def test_bad_sections_name_the_key(section: Any, words: str) -> None:
    with pytest.raises(ProfileError) as info:
        parse_mqtt_section(section, source="p.yaml")
    assert words in str(info.value) and "p.yaml" in str(info.value)


def test_qos_profile_keeps_the_mqtt_section() -> None:
    profile = QoSProfile.from_string("mqtt:\n  topics: {/a: {}}\npublishers: {/a: {transport_priority: HIGH}}\n")
    assert profile.mqtt == {"topics": {"/a": {}}} and profile.advertise_options("/a") is not None
