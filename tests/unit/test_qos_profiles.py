"""Unit tests of micros_rt.qos.profiles: YAML format, lookup precedence, merge rule, error messages."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import pytest

from micros_rt.exceptions import ProfileError
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority
from micros_rt.qos.profiles import QoSProfile, merge_advertise, merge_subscribe

P = TransportPriority

EXAMPLE = """\
publishers:
  /chatter: {transport_priority: HIGH, latency_budget: 0.005}
  "/camera/*": {using_best_effort_protocol: true, msg_valid_period: 0.1}
subscribers:
  /chatter: {time_filter_duration: 1.0, deadline: 0.5}
"""


def parse(text: str) -> QoSProfile:
    return QoSProfile.from_string(textwrap.dedent(text), source="qos.yaml")


def error_of(text: str) -> str:
    with pytest.raises(ProfileError) as info:
        parse(text)
    return str(info.value)


# --- format --------------------------------------------------------------------------------------


def test_example_from_the_docs() -> None:
    profile = parse(EXAMPLE)
    assert profile.advertise_options("/chatter") == AdvertiseQoSOptions(
        transport_priority=P.HIGH, latency_budget=0.005
    )
    assert profile.advertise_options("/camera/rgb") == AdvertiseQoSOptions(
        using_best_effort_protocol=True, msg_valid_period=0.1
    )
    assert profile.subscribe_options("/chatter") == SubscribeQoSOptions(
        deadline=0.5, time_filter_duration=1.0
    )
    assert profile.subscribe_options("/camera/rgb") is None
    assert profile.advertise_options("/other") is None
    assert profile.source == "qos.yaml"


def test_load_from_file(tmp_path: Path) -> None:
    path = tmp_path / "qos.yaml"
    path.write_text(EXAMPLE, encoding="utf-8")
    profile = QoSProfile.load(path)
    assert profile.source == str(path)
    assert profile.advertise_options("/chatter") == AdvertiseQoSOptions(P.HIGH, 0.005)
    assert QoSProfile.load(str(path)).publishers == profile.publishers


def test_load_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match="nope.yaml: cannot read QoS profile"):
        QoSProfile.load(tmp_path / "nope.yaml")


@pytest.mark.parametrize("text", ["", "# only a comment\n", "publishers:\nsubscribers:\n"])
def test_empty_profiles(text: str) -> None:
    profile = parse(text)
    assert profile.publishers == {} and profile.subscribers == {}
    assert profile.advertise_options("/chatter") is None


def test_empty_options_mapping_means_defaults() -> None:
    profile = parse("publishers:\n  /a: {}\n  /b:\nsubscribers:\n  /a: {}\n")
    assert profile.advertise_options("/a") == AdvertiseQoSOptions()
    assert profile.advertise_options("/b") == AdvertiseQoSOptions()
    assert profile.subscribe_options("/a") == SubscribeQoSOptions()


def test_all_publisher_options_and_value_spellings() -> None:
    profile = parse(
        """
        publishers:
          /a: {transport_priority: extremely_low, latency_budget: 2, using_best_effort_protocol: false,
               data_centric_update: false, msg_valid_period: .inf}
          /b: {transport_priority: 6, latency_budget: inf, msg_valid_period: "0.25"}
          /c: {transport_priority: VeryHigh}
        """
    )
    assert profile.advertise_options("/a") == AdvertiseQoSOptions(P.EXTREMELY_LOW, 2.0, False, False, math.inf)
    assert profile.advertise_options("/b") == AdvertiseQoSOptions(
        P.EXTREMELY_HIGH, math.inf, msg_valid_period=0.25
    )
    options_c = profile.advertise_options("/c")
    assert options_c is not None and options_c.transport_priority is P.VERY_HIGH


def test_all_subscriber_options() -> None:
    profile = parse(
        """
        subscribers:
          /s:
            deadline: 0.2
            ordered_by_sending_timestamp: false
            time_filter_duration: 0.05
            using_best_effort_protocol: true
            data_centric_update: false
        """
    )
    assert profile.subscribe_options("/s") == SubscribeQoSOptions(0.2, None, False, 0.05, True, False)


def test_constructed_in_code() -> None:
    profile = QoSProfile(publishers={"/x/*": AdvertiseQoSOptions(P.LOW)})
    assert profile.advertise_options("/x/y") == AdvertiseQoSOptions(P.LOW)
    assert profile.subscribe_options("/x/y") is None
    assert "/x/*" in repr(profile)


# --- lookup precedence ---------------------------------------------------------------------------

PRECEDENCE = """\
publishers:
  "*": {transport_priority: 0}
  "/camera/*": {transport_priority: 1}
  "/camera/*/image": {transport_priority: 2}
  /camera/front/image: {transport_priority: 3}
  "/camera/?ack/image": {transport_priority: 4}
  "/lidar/[ab]": {transport_priority: 5}
  "/x*": {transport_priority: 6}
  "*/y": {transport_priority: 5}
"""


@pytest.mark.parametrize(
    "topic, level",
    [
        ("/camera/front/image", 3),  # exact beats every pattern
        ("/camera/rear/image", 2),  # longest matching pattern
        ("/camera/back/image", 4),  # "/camera/?ack/image" is longer than "/camera/*/image"
        ("/camera/info", 1),
        ("/camera/a/b/c", 1),  # fnmatch's * spans slashes
        ("/lidar/a", 5),
        ("/lidar/c", 0),
        ("/chatter", 0),
        ("/xy", 6),  # "/x*" and "*/y" tie on length: the first in the file wins
    ],
)
def test_lookup_precedence(topic: str, level: int) -> None:
    options = parse(PRECEDENCE).advertise_options(topic)
    assert options is not None
    assert int(options.transport_priority) == level


def test_lookup_is_case_sensitive() -> None:
    profile = parse("publishers:\n  /Chatter: {transport_priority: HIGH}\n  '/Cam*': {}\n")
    assert profile.advertise_options("/chatter") is None
    assert profile.advertise_options("/cam1") is None


def test_sections_are_independent() -> None:
    profile = parse("subscribers:\n  '*': {deadline: 1.0}\n")
    assert profile.subscribe_options("/anything") == SubscribeQoSOptions(deadline=1.0)
    assert profile.advertise_options("/anything") is None


# --- errors --------------------------------------------------------------------------------------


def test_bad_value_names_file_line_key() -> None:
    message = error_of(
        """\
        publishers:
          /chatter: {transport_priority: HIGH}
        subscribers:
          /chatter: {time_filter_duration: abc}
        """
    )
    assert message.startswith(
        "qos.yaml:4: subscribers['/chatter'].time_filter_duration: 'abc' is invalid: expected a duration"
    )


def test_bad_value_in_block_style_points_at_its_own_line() -> None:
    message = error_of(
        """\
        publishers:
          /chatter:
            transport_priority: HIGH
            latency_budget: -1
        """
    )
    assert message.startswith("qos.yaml:4: publishers['/chatter'].latency_budget: -1 is invalid:")
    assert ">= 0" in message


def test_bad_priority_lists_allowed_values() -> None:
    message = error_of("publishers:\n  /a: {transport_priority: urgent}\n")
    assert message.startswith("qos.yaml:2: publishers['/a'].transport_priority: 'urgent' is invalid:")
    assert "EXTREMELY_LOW" in message and "EXTREMELY_HIGH" in message


@pytest.mark.parametrize(
    "text, start",
    [
        ("publishers:\n  /a: {using_best_effort_protocol: 1}\n", "qos.yaml:2: publishers['/a'].using_best_effort_protocol: 1 is invalid:"),
        ("subscribers:\n  /a: {ordered_by_sending_timestamp: 'no'}\n", "qos.yaml:2: subscribers['/a'].ordered_by_sending_timestamp: 'no' is invalid:"),
        ("subscribers:\n  /a: {deadline: 0}\n", "qos.yaml:2: subscribers['/a'].deadline: 0 is invalid:"),
    ],
)
def test_bad_values_of_each_kind(text: str, start: str) -> None:
    assert error_of(text).startswith(start)


def test_data_centric_update_is_refused_with_its_reason() -> None:
    message = error_of("subscribers:\n  /a: {data_centric_update: true}\n")
    assert message.startswith(
        "qos.yaml:2: subscribers['/a'].data_centric_update: data_centric_update=True is not supported"
    )
    assert "no key fields" in message


def test_unknown_section() -> None:
    message = error_of("publishers: {}\nservices:\n  /x: {}\n")
    assert message == "qos.yaml:2: unknown section 'services'; expected 'publishers', 'subscribers', 'links', 'mqtt', 'ros2'"


def test_unknown_option_lists_known_ones() -> None:
    message = error_of("publishers:\n  /a:\n    transport_priority: HIGH\n    priority: 3\n")
    assert message.startswith("qos.yaml:4: publishers['/a'].priority: unknown option; known options:")
    assert "msg_valid_period" in message and "latency_budget" in message


def test_publisher_option_in_subscriber_section() -> None:
    message = error_of("subscribers:\n  /a: {latency_budget: 0.1}\n")
    assert message.startswith("qos.yaml:2: subscribers['/a'].latency_budget: unknown option")


def test_deadline_cb_is_explained() -> None:
    message = error_of("subscribers:\n  /a: {deadline: 1.0, deadline_cb: my_callback}\n")
    assert message.startswith("qos.yaml:2: subscribers['/a'].deadline_cb: deadline callbacks cannot be")
    assert "in code" in message


@pytest.mark.parametrize(
    "text, start",
    [
        ("- publishers\n", "qos.yaml:1: the top level: expected a mapping"),
        ("just text\n", "qos.yaml:1: the top level: expected a mapping"),
        ("publishers:\n  - /a\n", "qos.yaml:2: publishers: expected a mapping of topic names"),
        ("publishers:\n  /a: HIGH\n", "qos.yaml:2: publishers['/a']: expected a mapping of option names"),
        ("publishers:\n  /a: [1, 2]\n", "qos.yaml:2: publishers['/a']: expected a mapping of option names"),
        ("publishers:\n  /a: {latency_budget: [1]}\n", "qos.yaml:2: publishers['/a'].latency_budget: expected a single value"),
    ],
)
def test_non_mapping_content(text: str, start: str) -> None:
    assert error_of(text).startswith(start)


def test_duplicate_keys_are_errors() -> None:
    message = error_of("publishers:\n  /a: {}\n  /a: {transport_priority: HIGH}\n")
    assert message == "qos.yaml:3: publishers['/a']: duplicate key (first given on line 2)"
    message = error_of("publishers:\n  /a: {latency_budget: 1, latency_budget: 2}\n")
    assert message == "qos.yaml:2: publishers['/a'].latency_budget: duplicate key (first given on line 2)"
    message = error_of("publishers: {}\nsubscribers: {}\npublishers: {}\n")
    assert message == "qos.yaml:3: publishers: duplicate key (first given on line 1)"


def test_non_string_keys_are_errors() -> None:
    assert error_of("publishers:\n  42: {}\n").startswith("qos.yaml:2: publishers: key '42' must be a string")


def test_invalid_yaml() -> None:
    message = error_of("publishers: {/a: [\n")
    assert message.startswith("qos.yaml: not valid YAML:")


def test_profile_error_keeps_the_cause() -> None:
    with pytest.raises(ProfileError) as info:
        parse("publishers:\n  /a: {latency_budget: -1}\n")
    assert isinstance(info.value.__cause__, ValueError)


# --- merge ---------------------------------------------------------------------------------------


def test_merge_advertise_per_field() -> None:
    code = AdvertiseQoSOptions(transport_priority=P.HIGH)
    profile = AdvertiseQoSOptions(
        transport_priority=P.LOW, latency_budget=0.01, using_best_effort_protocol=True, msg_valid_period=0.5
    )
    assert merge_advertise(code, profile) == AdvertiseQoSOptions(P.HIGH, 0.01, True, False, 0.5)


def test_merge_advertise_code_non_defaults_all_win() -> None:
    code = AdvertiseQoSOptions(P.VERY_LOW, 0.2, True, False, 3.0)
    profile = AdvertiseQoSOptions(P.EXTREMELY_HIGH, 0.01, False, False, 0.5)
    assert merge_advertise(code, profile) == code


def test_merge_advertise_with_missing_sides() -> None:
    options = AdvertiseQoSOptions(P.HIGH)
    assert merge_advertise(None, options) == options
    assert merge_advertise(options, None) == options
    assert merge_advertise(None, None) == AdvertiseQoSOptions()


def test_merge_code_value_equal_to_default_yields_to_file() -> None:
    # Documented limitation: an explicit default cannot be told apart from "not given".
    code = AdvertiseQoSOptions(transport_priority=P.NORMAL)
    assert merge_advertise(code, AdvertiseQoSOptions(P.LOW)).transport_priority is P.LOW


def test_merge_subscribe_per_field_and_keeps_code_callback() -> None:
    def on_miss(_event: object) -> None:
        pass

    code = SubscribeQoSOptions(deadline=0.1, deadline_cb=on_miss, ordered_by_sending_timestamp=False)
    profile = SubscribeQoSOptions(deadline=2.0, time_filter_duration=0.5, using_best_effort_protocol=True)
    merged = merge_subscribe(code, profile)
    assert merged.deadline == 0.1
    assert merged.deadline_cb is on_miss
    assert merged.ordered_by_sending_timestamp is False
    assert merged.time_filter_duration == 0.5
    assert merged.using_best_effort_protocol is True


def test_merge_subscribe_profile_deadline_applies_when_code_has_none() -> None:
    merged = merge_subscribe(SubscribeQoSOptions(time_filter_duration=0.2), SubscribeQoSOptions(deadline=0.3))
    assert (merged.deadline, merged.time_filter_duration, merged.deadline_cb) == (0.3, 0.2, None)


def test_merge_subscribe_with_missing_sides() -> None:
    options = SubscribeQoSOptions(deadline=1.0)
    assert merge_subscribe(None, options) == options
    assert merge_subscribe(options, None) == options
    assert merge_subscribe(None, None) == SubscribeQoSOptions()


def test_merge_with_a_loaded_profile() -> None:
    profile = parse(EXAMPLE)
    merged = merge_advertise(AdvertiseQoSOptions(latency_budget=0.001), profile.advertise_options("/chatter"))
    assert merged == AdvertiseQoSOptions(P.HIGH, 0.001)


# -- transport_hints (subscribers and publishers) -------------------------------------------------------------

def test_subscriber_transport_hints_are_read_in_order_and_looked_up_like_options() -> None:
    from micros_rt.negotiation import TransportHints

    p = QoSProfile.from_string(
        "subscribers:\n"
        "  /camera/*: {transport_hints: [tcpros]}\n"
        "  /scan: {transport_hints: [TCPROS, DDS], deadline: 1.0}\n"
        "  /odom: {deadline: 0.5}\n", source="robot.yaml")
    assert p.subscribe_transports("/camera/image") == ("TCPROS",)
    assert p.subscribe_transports("/scan") == ("TCPROS", "DDS")
    scan = p.subscribe_options("/scan")
    assert scan is not None and scan.deadline == 1.0  # the other options of the entry still apply
    assert p.subscribe_transports("/odom") is None and p.subscribe_transports("/other") is None
    hints = TransportHints.from_names(p.subscribe_transports("/scan") or ())
    assert hints == TransportHints().tcp().dds() and hints.protocols == ("TCPROS", "DDS")
    assert not TransportHints.from_names(("TCPROS",)).allows_dds


@pytest.mark.parametrize("value, says", [
    ("UDPROS", "got the value 'UDPROS'"),
    ("[UDPROS]", "'UDPROS' is not a transport"),
    ("[DDS, dds]", "DDS is given twice"),
    ("[]", "expected a list of 'SHM', 'DDS' and 'TCPROS'"),
    ("{a: 1}", "got a mapping"),
])
def test_bad_transport_hints_are_refused_with_file_line_and_key(value: str, says: str) -> None:
    with pytest.raises(ProfileError) as err:
        QoSProfile.from_string(f"subscribers:\n  /x: {{deadline: 1.0}}\n  /a:\n    transport_hints: {value}\n",
                               source="robot.yaml")
    assert str(err.value).startswith("robot.yaml:4: subscribers['/a'].transport_hints: ") and says in str(err.value)


def test_a_publishers_transport_hints_say_what_it_serves_and_must_keep_tcpros() -> None:
    p = QoSProfile.from_string(
        "publishers:\n"
        "  /camera/*: {transport_hints: [tcpros], transport_priority: LOW}\n"
        "  /scan: {transport_hints: [DDS, TCPROS]}\n"
        "  /odom: {transport_priority: HIGH}\n", source="robot.yaml")
    assert p.advertise_transports("/camera/image") == ("TCPROS",)
    assert p.advertise_transports("/scan") == ("DDS", "TCPROS")
    assert p.advertise_transports("/odom") is None and p.subscribe_transports("/camera/image") is None
    camera = p.advertise_options("/camera/image")
    assert camera is not None and camera.transport_priority == P.LOW  # the entry's other options still apply
    with pytest.raises(ProfileError) as err:
        QoSProfile.from_string("publishers:\n  /a:\n    transport_hints: [DDS]\n", source="robot.yaml")
    assert str(err.value).startswith("robot.yaml:3: publishers['/a'].transport_hints: a publisher always serves "
                                     "TCPROS")
    with pytest.raises(ValueError, match="unknown transport 'UDP'"):
        from micros_rt.negotiation import TransportHints
        TransportHints.from_names(["UDP"])
