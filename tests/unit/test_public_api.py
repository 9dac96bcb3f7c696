"""The public surface: names promised by the issue exist, __all__ is honest, hints and config are right."""

from __future__ import annotations

import inspect

import pytest

import micros_rt
from micros_rt import TransportHints
from micros_rt.transports.dds.endpoints import make_user_data, parse_user_data
from micros_rt.transports.dds.participant import LOOPBACK_CONFIG, cyclone_config, domain_id_from_env
from micros_rt.transports.dds.types import dds_topic_name, dds_type_name
from micros_rt.exceptions import DDSUnavailableError, MicrosRtError


def test_all_is_honest() -> None:
    for name in micros_rt.__all__:
        assert hasattr(micros_rt, name), name
    # subpackages (dds, qos, cli, mqtt, ...) become attributes once anything imports them
    public = {n for n in dir(micros_rt) if not n.startswith("_") and not inspect.ismodule(getattr(micros_rt, n))}
    assert public == set(micros_rt.__all__)


@pytest.mark.parametrize("name", ["init_node", "spin", "is_shutdown", "ok", "shutdown", "NodeHandle",
                                  "TransportPriority", "AdvertiseQoSOptions", "SubscribeQoSOptions",
                                  "TransportHints"])
def test_issue_names_exist(name: str) -> None:
    assert name in micros_rt.__all__


def test_nodehandle_signatures() -> None:
    nh = micros_rt.NodeHandle
    assert list(inspect.signature(nh.advertise).parameters)[:5] == ["self", "topic", "data_class", "queue_size",
                                                                    "latch"]
    assert list(inspect.signature(nh.advertise_with_qos).parameters)[:6] == [
        "self", "topic", "data_class", "queue_size", "qos", "latch"]
    assert list(inspect.signature(nh.subscribe).parameters)[:6] == [
        "self", "topic", "data_class", "callback", "queue_size", "transport_hints"]
    assert list(inspect.signature(nh.subscribe_with_qos).parameters)[:6] == [
        "self", "topic", "data_class", "callback", "queue_size", "qos"]


def test_priority_levels() -> None:
    names = [p.name for p in micros_rt.TransportPriority]
    assert names == ["EXTREMELY_LOW", "VERY_LOW", "LOW", "NORMAL", "HIGH", "VERY_HIGH", "EXTREMELY_HIGH"]
    assert micros_rt.AdvertiseQoSOptions().transport_priority is micros_rt.TransportPriority.NORMAL


@pytest.mark.parametrize("hints,order", [
    (TransportHints(), ("SHM", "DDS", "TCPROS")),
    (TransportHints().tcp(), ("TCPROS",)),
    (TransportHints().shm().tcp(), ("SHM", "TCPROS")),
    (TransportHints().dds().shm(), ("DDS", "SHM")),
    (TransportHints().dds(), ("DDS",)),
    (TransportHints().dds().tcp(), ("DDS", "TCPROS")),
    (TransportHints().tcp().dds(), ("TCPROS", "DDS")),
    (TransportHints().tcp().tcp().dds(), ("TCPROS", "DDS")),
])
def test_transport_hints_order(hints: TransportHints, order: tuple[str, ...]) -> None:
    assert hints.protocols == order
    assert hints.allows_dds == ("DDS" in order)
    assert hints.allows_tcp == ("TCPROS" in order)
    assert hints.allows_shm == ("SHM" in order)
    assert TransportHints.from_names(list(order)) == hints


def test_transport_hints_are_immutable() -> None:
    base = TransportHints()
    tcp = base.tcp()
    assert base.protocols == ("SHM", "DDS", "TCPROS") and tcp.protocols == ("TCPROS",)
    assert repr(TransportHints().tcp().dds()) == "TransportHints().tcp().dds()"
    assert repr(TransportHints().shm().tcp()) == "TransportHints().shm().tcp()"


def test_names_on_dds() -> None:
    assert dds_topic_name("/chatter") == "rt/chatter"
    assert dds_topic_name("/ns/scan") == "rt/ns/scan"
    assert dds_type_name("std_msgs/String") == "std_msgs::msg::dds_::String_"
    assert dds_type_name("time") == "builtin_interfaces::msg::dds_::Time_"


@pytest.mark.parametrize("env,loopback", [
    ({"ROS_IP": "127.0.0.1"}, True),
    ({"ROS_HOSTNAME": "localhost"}, True),
    ({"ROS_IP": "::1"}, True),
    ({"ROS_IP": "10.1.2.3"}, False),
])
def test_cyclone_config_follows_ros_ip(env: dict[str, str], loopback: bool) -> None:
    cfg = cyclone_config(env)
    assert (LOOPBACK_CONFIG in cfg) == loopback
    if not loopback:
        assert 'address="10.1.2.3"' in cfg


def test_loopback_config_never_multicasts() -> None:
    assert 'name="lo"' in LOOPBACK_CONFIG and 'multicast="false"' in LOOPBACK_CONFIG
    assert "<AllowMulticast>false</AllowMulticast>" in LOOPBACK_CONFIG
    assert '<Peer address="127.0.0.1"/>' in LOOPBACK_CONFIG


def test_cyclonedds_uri_wins() -> None:
    # the user's configuration comes last, so it overrides micros_rt's defaults where it speaks
    cfg = cyclone_config({"CYCLONEDDS_URI": "file:///x.xml", "ROS_IP": "127.0.0.1"})
    assert cfg.endswith(",file:///x.xml") and LOOPBACK_CONFIG not in cfg
    assert "<LeaseDuration>5s</LeaseDuration>" in cfg.split(",")[0]  # ROS_IP is loopback, shared memory on


@pytest.mark.parametrize("raw,expected", [("", 0), ("7", 7), ("232", 232)])
def test_domain_id(raw: str, expected: int) -> None:
    assert domain_id_from_env({"ROS_DOMAIN_ID": raw}) == expected


@pytest.mark.parametrize("raw", ["abc", "-1", "233"])
def test_bad_domain_id_is_a_clear_error(raw: str) -> None:
    with pytest.raises(DDSUnavailableError, match="ROS_DOMAIN_ID"):
        domain_id_from_env({"ROS_DOMAIN_ID": raw})
    assert issubclass(DDSUnavailableError, MicrosRtError)


def test_user_data_tag_round_trip() -> None:
    tag = make_user_data(graph="abc@http://h:1/", node="/talker")
    assert parse_user_data(tag) == {"graph": "abc@http://h:1/", "node": "/talker"}
    assert parse_user_data(b"typehash=RIHS01_00;") is None  # a ROS 2 writer
    assert parse_user_data(None) is None


def test_node_handle_before_init_is_a_clear_error() -> None:
    from std_msgs.msg import String

    with pytest.raises(micros_rt.NodeNotInitializedError, match="init_node"):
        micros_rt.NodeHandle().advertise("x", String, 1)
