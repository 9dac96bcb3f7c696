"""The MQTT bridge's parameter file: mqtt_client's layout (ROS 1), read from YAML, validated, with
mqtt_client's defaults.

The layout is mqtt_client's (``broker``, ``client``, ``bridge.ros2mqtt[]``, ``bridge.mqtt2ros[]``). The
connection's part (``broker``, ``client``) is the MQTT transport's
(:mod:`micros_rt.transports.mqtt.params`); this module reads the bridge's topic mappings. A parameter that
has a default and is not set is logged as mqtt_client logs it (``Parameter 'client/id' not set, defaulting
to ''``). Unknown keys and bad values are errors naming the parameter, where mqtt_client would ignore or
misread them.

micros_rt additions (never needed by an mqtt_client params file): ``bridge.ros2mqtt[].json`` /
``bridge.mqtt2ros[].json`` (every field as JSON, for non-ROS clients) and ``bridge.mqtt2ros[].ros_type`` (fix
the ROS type, as in mqtt_client's ROS 2 version).

``bridge.mqtt_client_version`` (micros_rt; ``2`` or ``1``) fixes the wire the bridge writes: mqtt_client 2.x
(2.0-2.3 for ROS 1: no flag byte, ``RosMsgType.stamped``) or 1.x (a flag byte, a three-string
``RosMsgType``); ``bridge.ros2mqtt[].mqtt_client_version`` fixes one topic's. Unset, each topic is written
in the generation the peers' type announcements on the broker speak (2.x when none are there; see
:mod:`~micros_rt.transports.mqtt.generations`). Both are read whatever it says. mqtt_client ignores the keys.

>>> params, warnings = parse_params({"bridge": {"mqtt2ros": [{"mqtt_topic": "a", "ros_topic": "/a"}]}})
>>> params.broker.port, warnings[0]
(1883, "Parameter 'broker/tls/enabled' not set, defaulting to '0'")
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, List, Mapping, Optional, Sequence, Tuple

import yaml

from ...transports.mqtt.codec import WireGeneration
from ...transports.mqtt.params import (ConnectionParams, ParamsError, ParamsReader, parse_connection, parse_wire)

__all__ = [
    "Mqtt2RosParams",
    "MqttParams",
    "ParamsError",
    "Ros2MqttParams",
    "load_params",
    "parse_params",
]


@dataclasses.dataclass(frozen=True)
class Ros2MqttParams:
    """One ``bridge.ros2mqtt[]`` entry."""

    ros_topic: str
    mqtt_topic: str
    primitive: bool = False
    json: bool = False
    inject_timestamp: bool = False
    queue_size: int = 1
    qos: int = 0
    retained: bool = False
    #: ``mqtt_client_version`` of this entry (micros_rt): the generation written on this topic, whatever
    #: the peers on the broker speak; None: ``bridge/mqtt_client_version``, else the peers' (see generations)
    wire: Optional[WireGeneration] = None


@dataclasses.dataclass(frozen=True)
class Mqtt2RosParams:
    """One ``bridge.mqtt2ros[]`` entry."""

    mqtt_topic: str
    ros_topic: str
    primitive: bool = False
    json: bool = False
    ros_type: str = ""
    qos: int = 0
    queue_size: int = 1
    latched: bool = False


@dataclasses.dataclass(frozen=True)
class MqttParams(ConnectionParams):
    """The whole parameter set: the connection's (``broker``, ``client``) and the bridge's topics."""

    ros2mqtt: Tuple[Ros2MqttParams, ...]
    mqtt2ros: Tuple[Mqtt2RosParams, ...]
    #: the mqtt_client wire written (``bridge/mqtt_client_version``) when the peers on the broker do not say;
    #: both are read
    wire: WireGeneration = WireGeneration.V2
    #: ``bridge/mqtt_client_version`` was set: it overrides what the peers on the broker speak
    wire_set: bool = False


def _qos(r: ParamsReader, data: Mapping[str, Any], name: str) -> int:
    value: int = r.get(data, "qos", name, int, 0, warn=False, lo=0, hi=2)
    return value


def parse_params(data: Any, *, source: str = "params") -> Tuple[MqttParams, List[str]]:
    """Validate a parsed YAML document; return the parameters and mqtt_client's default warnings."""
    r = ParamsReader(source)
    if not isinstance(data, Mapping):
        raise ParamsError(f"{source}: must be a mapping with 'broker', 'client' and 'bridge', got {data!r}")
    r.check_keys(data, ("broker", "client", "bridge"), "")
    broker, client = parse_connection(r, data)

    bridge = data.get("bridge")
    if bridge is None:
        raise ParamsError(f"{source}: parameter 'bridge' is required")
    bridge = r.section(data, "bridge", "bridge")
    r.check_keys(bridge, ("ros2mqtt", "mqtt2ros", "mqtt_client_version"), "bridge")
    wire = parse_wire(r, bridge, "bridge/mqtt_client_version")
    wire_set = bridge.get("mqtt_client_version") is not None
    ros2mqtt = tuple(_ros2mqtt(r, e, k) for k, e in enumerate(_entries(r, bridge, "ros2mqtt")))
    mqtt2ros = tuple(_mqtt2ros(r, e, k) for k, e in enumerate(_entries(r, bridge, "mqtt2ros")))
    if not ros2mqtt and not mqtt2ros:
        raise ParamsError(f"{source}: no valid ROS-MQTT bridge found in parameter 'bridge' "
                          "(give 'bridge/ros2mqtt' or 'bridge/mqtt2ros' entries)")
    _no_duplicates(r, [e.ros_topic for e in ros2mqtt], "bridge/ros2mqtt", "ros_topic")
    _no_duplicates(r, [e.mqtt_topic for e in mqtt2ros], "bridge/mqtt2ros", "mqtt_topic")
    return MqttParams(broker, client, ros2mqtt, mqtt2ros, wire, wire_set), r.warnings


def _entries(r: ParamsReader, bridge: Mapping[str, Any], key: str) -> List[Mapping[str, Any]]:
    value = bridge.get(key)
    if value is None:
        return []
    if not isinstance(value, list) or not all(isinstance(e, Mapping) for e in value):
        raise r.fail(f"bridge/{key}", f"must be a list of mappings, got {value!r}")
    return value


def _topic(r: ParamsReader, data: Mapping[str, Any], key: str, name: str) -> str:
    value = r.get(data, key, f"{name}/{key}", str)
    if not value:
        raise r.fail(f"{name}/{key}", "is required (a non-empty topic name)")
    if key == "mqtt_topic" and any(ch in value for ch in "+#"):
        raise r.fail(f"{name}/{key}", f"is {value!r}: MQTT wildcards '+' and '#' cannot name one ROS topic")
    return str(value)


def _advanced(r: ParamsReader, e: Mapping[str, Any], name: str, ros_keys: Sequence[str],
              mqtt_keys: Sequence[str]) -> Tuple[Mapping[str, Any], Mapping[str, Any]]:
    """An entry's ``advanced.ros`` and ``advanced.mqtt`` sections, their keys checked."""
    adv = r.section(e, "advanced", f"{name}/advanced")
    r.check_keys(adv, ("ros", "mqtt"), f"{name}/advanced")
    ros = r.section(adv, "ros", f"{name}/advanced/ros")
    r.check_keys(ros, ros_keys, f"{name}/advanced/ros")
    mqtt = r.section(adv, "mqtt", f"{name}/advanced/mqtt")
    r.check_keys(mqtt, mqtt_keys, f"{name}/advanced/mqtt")
    return ros, mqtt


def _ros2mqtt(r: ParamsReader, e: Mapping[str, Any], k: int) -> Ros2MqttParams:
    name = f"bridge/ros2mqtt[{k}]"
    r.check_keys(e, ("ros_topic", "mqtt_topic", "primitive", "json", "inject_timestamp", "advanced",
                     "mqtt_client_version"), name)
    ros, mqtt = _advanced(r, e, name, ("queue_size",), ("qos", "retained"))
    entry = Ros2MqttParams(
        ros_topic=_topic(r, e, "ros_topic", name),
        mqtt_topic=_topic(r, e, "mqtt_topic", name),
        primitive=r.get(e, "primitive", f"{name}/primitive", bool, False, warn=False),
        json=r.get(e, "json", f"{name}/json", bool, False, warn=False),
        inject_timestamp=r.get(e, "inject_timestamp", f"{name}/inject_timestamp", bool, False, warn=False),
        queue_size=r.get(ros, "queue_size", f"{name}/advanced/ros/queue_size", int, 1, warn=False, lo=1, hi=1e6),
        qos=_qos(r, mqtt, f"{name}/advanced/mqtt/qos"),
        retained=r.get(mqtt, "retained", f"{name}/advanced/mqtt/retained", bool, False, warn=False),
        wire=(parse_wire(r, e, f"{name}/mqtt_client_version") if e.get("mqtt_client_version") is not None
              else None),
    )
    if entry.primitive and entry.json:
        raise r.fail(f"{name}/json", "and 'primitive' cannot both be true: choose one payload format")
    return entry


def _mqtt2ros(r: ParamsReader, e: Mapping[str, Any], k: int) -> Mqtt2RosParams:
    name = f"bridge/mqtt2ros[{k}]"
    r.check_keys(e, ("mqtt_topic", "ros_topic", "primitive", "json", "ros_type", "advanced"), name)
    ros, mqtt = _advanced(r, e, name, ("queue_size", "latched"), ("qos",))
    entry = Mqtt2RosParams(
        mqtt_topic=_topic(r, e, "mqtt_topic", name),
        ros_topic=_topic(r, e, "ros_topic", name),
        primitive=r.get(e, "primitive", f"{name}/primitive", bool, False, warn=False),
        json=r.get(e, "json", f"{name}/json", bool, False, warn=False),
        ros_type=r.get(e, "ros_type", f"{name}/ros_type", str, "", warn=False),
        qos=_qos(r, mqtt, f"{name}/advanced/mqtt/qos"),
        queue_size=r.get(ros, "queue_size", f"{name}/advanced/ros/queue_size", int, 1, warn=False, lo=1, hi=1e6),
        latched=r.get(ros, "latched", f"{name}/advanced/ros/latched", bool, False, warn=False),
    )
    if entry.primitive and entry.json:
        raise r.fail(f"{name}/json", "and 'primitive' cannot both be true: choose one payload format")
    if entry.json and not entry.ros_type:
        raise r.fail(f"{name}/ros_type", "is required with 'json: true' (JSON carries no ROS type)")
    if entry.ros_type and "/" not in entry.ros_type:
        raise r.fail(f"{name}/ros_type", f"is {entry.ros_type!r}: expected 'package/Type', e.g. 'std_msgs/Int32'")
    return entry


def _no_duplicates(r: ParamsReader, names: List[str], section: str, key: str) -> None:
    seen = set()
    for k, n in enumerate(names):
        if n in seen:
            raise r.fail(f"{section}[{k}]/{key}", f"repeats {n!r}: each may be bridged once")
        seen.add(n)


def load_params(path: "str | os.PathLike[str]") -> Tuple[MqttParams, List[str]]:
    """Read and validate a params file (a missing file or bad YAML is a :class:`ParamsError`)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParamsError(f"cannot read params file {str(p)!r}: {exc.strerror or exc}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ParamsError(f"{p}: not valid YAML: {exc}") from exc
    return parse_params(data, source=str(p))
