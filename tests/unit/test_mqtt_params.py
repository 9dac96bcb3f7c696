"""mqtt_client's parameter layout: defaults, mqtt_client's default warnings, errors naming the parameter."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict

import pytest

from micros_rt.bridges.mqtt.params import ParamsError, load_params, parse_params
from micros_rt.transports.mqtt.params import resolve_path

MINIMAL: Dict[str, Any] = {"bridge": {"ros2mqtt": [{"ros_topic": "/ping/ros", "mqtt_topic": "pingpong/ros"}]}}


def test_defaults_and_warnings_as_mqtt_client_logs_them() -> None:
    params, warnings = parse_params({"broker": {"host": "localhost", "port": 1883}, **MINIMAL})
    assert warnings == [
        "Parameter 'broker/tls/enabled' not set, defaulting to '0'",
        "Parameter 'client/id' not set, defaulting to ''",
        "Client buffer can not be enabled when client ID is empty",
        "Parameter 'client/clean_session' not set, defaulting to '1'",
        "Parameter 'client/keep_alive_interval' not set, defaulting to '60.000000'",
        "Parameter 'client/max_inflight' not set, defaulting to '65535'",
    ]
    b, c, (r,) = params.broker, params.client, params.ros2mqtt
    assert (b.host, b.port, b.user, b.tls_enabled, b.tls_ca_certificate) == (
        "localhost", 1883, "", False, "/etc/ssl/certs/ca-certificates.crt")
    assert (c.id, c.buffer_size, c.buffer_directory, c.clean_session, c.keep_alive_interval, c.max_inflight) == (
        "", 0, "buffer", True, 60.0, 65535)
    assert not c.buffer_enabled and c.last_will_topic == ""
    assert (r.primitive, r.inject_timestamp, r.queue_size, r.qos, r.retained) == (False, False, 1, 0, False)


def test_every_parameter() -> None:
    data = {
        "broker": {"host": "10.0.0.1", "port": 8883, "user": "robot", "pass": 1234,
                   "tls": {"enabled": True, "ca_certificate": "ca.crt"}},
        "client": {"id": "r1", "buffer": {"size": 100, "directory": "/tmp/buf", "max_age": 5},
                   "last_will": {"topic": "r1/status", "message": "gone", "qos": 1, "retained": True},
                   "clean_session": False, "keep_alive_interval": 2, "max_inflight": 10, "max_packet_size": 2048,
                   "tls": {"certificate": "c.crt", "key": "c.key", "password": "pw"}},
        "bridge": {
            "ros2mqtt": [{"ros_topic": "/a", "mqtt_topic": "a", "primitive": True, "inject_timestamp": True,
                          "advanced": {"ros": {"queue_size": 5}, "mqtt": {"qos": 2, "retained": True}}}],
            "mqtt2ros": [{"mqtt_topic": "b", "ros_topic": "/b", "json": True, "ros_type": "std_msgs/Int32",
                          "advanced": {"mqtt": {"qos": 1}, "ros": {"queue_size": 3, "latched": True}}}],
        },
    }
    params, warnings = parse_params(data)
    assert warnings == []
    assert params.broker.password == "1234" and params.client.buffer_enabled
    assert params.client.keep_alive_interval == 2.0 and params.client.buffer_max_age == 5.0
    assert params.client.max_packet_size == 2048
    assert params.ros2mqtt[0].qos == 2 and params.mqtt2ros[0].latched and params.mqtt2ros[0].queue_size == 3


def test_last_will_defaults_are_warned_only_with_a_topic() -> None:
    _, warnings = parse_params({"client": {"last_will": {"topic": "x/status"}}, **MINIMAL})
    assert "Parameter 'client/last_will/message' not set, defaulting to 'offline'" in warnings
    assert "Parameter 'client/last_will/qos' not set, defaulting to '0'" in warnings


@pytest.mark.parametrize("data, words", [
    ({"brocker": {}, **MINIMAL}, "unknown parameter(s) 'brocker' in the top level"),
    ({"broker": {"port": "1883"}, **MINIMAL}, "'broker/port' must be an integer"),
    ({"broker": {"port": 70000}, **MINIMAL}, "'broker/port' is 70000, must be between 1 and 65535"),
    ({"broker": {"tls": {"enabled": "yes"}}, **MINIMAL}, "'broker/tls/enabled' must be true or false"),
    ({"client": {"keep_alive": 5}, **MINIMAL}, "unknown parameter(s) 'keep_alive' in 'client'"),
    ({"client": {"buffer": {"size": 10}}, **MINIMAL}, "'client/buffer/size' needs 'client/id'"),
    ({"client": {"tls": {"certificate": "c.crt"}}, **MINIMAL}, "'client/tls/key' must be given together"),
    ({"client": {"last_will": {"topic": "t", "qos": 3}}, **MINIMAL}, "'client/last_will/qos' is 3"),
    ({}, "parameter 'bridge' is required"),
    ({"bridge": {}}, "no valid ROS-MQTT bridge"),
    ({"bridge": {"ros2mqtt": {"ros_topic": "/a"}}}, "'bridge/ros2mqtt' must be a list"),
    ({"bridge": {"ros2mqtt": [{"ros_topic": "/a"}]}}, "'bridge/ros2mqtt[0]/mqtt_topic' is required"),
    ({"bridge": {"ros2mqtt": [{"ros_topic": "/a", "mqtt_topic": "a/#"}]}}, "wildcards"),
    ({"bridge": {"ros2mqtt": [{"ros_topic": "/a", "mqtt_topic": "a", "advanced": {"mqtt": {"qos": 5}}}]}},
     "'bridge/ros2mqtt[0]/advanced/mqtt/qos' is 5"),
    ({"bridge": {"ros2mqtt": [{"ros_topic": "/a", "mqtt_topic": "a", "primitve": True}]}},
     "unknown parameter(s) 'primitve' in 'bridge/ros2mqtt[0]'"),
    ({"bridge": {"mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a", "json": True}]}},
     "'bridge/mqtt2ros[0]/ros_type' is required with 'json: true'"),
    ({"bridge": {"mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a"}, {"mqtt_topic": "a", "ros_topic": "/b"}]}},
     "'bridge/mqtt2ros[1]/mqtt_topic' repeats 'a'"),
    ([1, 2], "must be a mapping"),
])
def test_errors_name_the_parameter(data: Any, words: str) -> None:
    with pytest.raises(ParamsError) as info:
        parse_params(data, source="p.yaml")
    assert words in str(info.value) and str(info.value).startswith("p.yaml")


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ParamsError, match="cannot read params file"):
        load_params(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("bridge: [\n")
    with pytest.raises(ParamsError, match="not valid YAML"):
        load_params(bad)


def test_relative_paths_resolve_against_ros_home() -> None:
    assert resolve_path("buffer", env={"ROS_HOME": "/home/r/.ros"}) == "/home/r/.ros/buffer"
    assert resolve_path("/abs/ca.crt", env={"ROS_HOME": "/x"}) == "/abs/ca.crt"
    assert resolve_path("", env={}) == ""
