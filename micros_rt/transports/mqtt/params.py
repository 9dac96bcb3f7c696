"""mqtt_client's parameter layout (ROS 1), read from a YAML file, validated, with mqtt_client's defaults.

The layout is mqtt_client's (``broker``, ``client``, ``bridge.ros2mqtt[]``, ``bridge.mqtt2ros[]``). A
parameter that has a default and is not set is logged as mqtt_client logs it (``Parameter 'client/id' not
set, defaulting to ''``). Unknown keys and bad values are errors naming the parameter, where mqtt_client
would ignore or misread them.

micros_rt additions (never needed by an mqtt_client params file): ``client.buffer.max_age`` (seconds a
buffered message stays valid, 0 = forever), ``client.max_packet_size`` (bytes; larger messages are dropped
and counted instead of making the broker close the connection, as AimRT's ``max_pkg_size_k``), ``bridge.ros2mqtt[].json`` / ``bridge.mqtt2ros[].json``
(every field as JSON, for non-ROS clients) and ``bridge.mqtt2ros[].ros_type`` (fix the ROS type, as in
mqtt_client's ROS 2 version).

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
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import yaml

from ...exceptions import MicrosRtError
from .codec import WireGeneration

__all__ = [
    "BrokerParams",
    "ClientParams",
    "Mqtt2RosParams",
    "MqttParams",
    "ParamsError",
    "Ros2MqttParams",
    "load_params",
    "parse_params",
    "resolve_path",
]


class ParamsError(MicrosRtError, ValueError):
    """A bad parameter file or value; the message names the file and the parameter."""


@dataclasses.dataclass(frozen=True)
class BrokerParams:
    """``broker.*``"""

    host: str = "localhost"
    port: int = 1883
    user: str = ""
    password: str = ""
    tls_enabled: bool = False
    tls_ca_certificate: str = "/etc/ssl/certs/ca-certificates.crt"


@dataclasses.dataclass(frozen=True)
class ClientParams:
    """``client.*``"""

    id: str = ""
    buffer_size: int = 0
    buffer_directory: str = "buffer"
    buffer_max_age: float = 0.0
    last_will_topic: str = ""
    last_will_message: str = "offline"
    last_will_qos: int = 0
    last_will_retained: bool = False
    clean_session: bool = True
    keep_alive_interval: float = 60.0
    max_inflight: int = 65535
    max_packet_size: int = 0
    tls_certificate: str = ""
    tls_key: str = ""
    tls_password: str = ""

    @property
    def buffer_enabled(self) -> bool:
        """mqtt_client buffers only with a client id (and a size above 0)."""
        return bool(self.id) and self.buffer_size > 0


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
class MqttParams:
    """The whole parameter set."""

    broker: BrokerParams
    client: ClientParams
    ros2mqtt: Tuple[Ros2MqttParams, ...]
    mqtt2ros: Tuple[Mqtt2RosParams, ...]
    #: the mqtt_client wire written (``bridge/mqtt_client_version``) when the peers on the broker do not say;
    #: both are read
    wire: WireGeneration = WireGeneration.V2
    #: ``bridge/mqtt_client_version`` was set: it overrides what the peers on the broker speak
    wire_set: bool = False


class _Reader:
    """Walks a nested mapping; every key read is remembered so that leftovers can be reported."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.warnings: List[str] = []

    def fail(self, name: str, problem: str) -> ParamsError:
        return ParamsError(f"{self.source}: parameter '{name}' {problem}")

    def section(self, data: Mapping[str, Any], key: str, name: str) -> Mapping[str, Any]:
        value = data.get(key)
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            raise self.fail(name, f"must be a mapping of parameters, got {value!r}")
        return value

    def check_keys(self, data: Mapping[str, Any], allowed: Sequence[str], name: str) -> None:
        unknown = [str(k) for k in data if k not in allowed]
        if unknown:
            where = f"'{name}'" if name else "the top level"
            raise ParamsError(f"{self.source}: unknown parameter(s) {', '.join(repr(u) for u in unknown)} in "
                              f"{where} (allowed: {', '.join(allowed)})")

    def get(self, data: Mapping[str, Any], key: str, name: str, kind: type, default: Any = None, *,
            warn: bool = True, lo: Optional[float] = None, hi: Optional[float] = None) -> Any:
        """The value of ``key`` as ``kind`` (bool, int, float, str); ``default`` (logged) when unset."""
        value = data.get(key)
        if value is None:
            if default is not None and warn:
                self.warnings.append(f"Parameter '{name}' not set, defaulting to '{_c_style(default)}'")
            return default
        if kind is bool:
            if not isinstance(value, bool):
                raise self.fail(name, f"must be true or false, got {value!r}")
        elif kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise self.fail(name, f"must be an integer, got {value!r}")
        elif kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self.fail(name, f"must be a number (seconds), got {value!r}")
            value = float(value)
        elif kind is str:
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                value = str(value)          # YAML reads a numeric password or client id as a number
            if not isinstance(value, str):
                raise self.fail(name, f"must be a string, got {value!r}")
        if isinstance(value, (int, float)) and (lo is not None and value < lo or hi is not None and value > hi):
            raise self.fail(name, f"is {value!r}, must be between {lo:g} and {hi:g}")
        return value


def _c_style(value: Any) -> str:
    """Defaults as mqtt_client's log shows them (C++ formatting): true -> 1, 60.0 -> 60.000000."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:.6f}"
    return str(value)


def _qos(r: _Reader, data: Mapping[str, Any], name: str) -> int:
    value: int = r.get(data, "qos", name, int, 0, warn=False, lo=0, hi=2)
    return value


def parse_connection(r: "_Reader", data: Mapping[str, Any]) -> Tuple[BrokerParams, ClientParams]:
    """The ``broker`` and ``client`` sections (shared by the bridge and the MQTT back end)."""
    b = r.section(data, "broker", "broker")
    r.check_keys(b, ("host", "port", "user", "pass", "tls"), "broker")
    btls = r.section(b, "tls", "broker/tls")
    r.check_keys(btls, ("enabled", "ca_certificate"), "broker/tls")
    user = r.get(b, "user", "broker/user", str, "", warn=False)
    tls_enabled = r.get(btls, "enabled", "broker/tls/enabled", bool, False)
    broker = BrokerParams(
        host=r.get(b, "host", "broker/host", str, "localhost"),
        port=r.get(b, "port", "broker/port", int, 1883, lo=1, hi=65535),
        user=user,
        password=r.get(b, "pass", "broker/pass", str, "", warn=bool(user)),
        tls_enabled=tls_enabled,
        tls_ca_certificate=r.get(btls, "ca_certificate", "broker/tls/ca_certificate", str,
                                 "/etc/ssl/certs/ca-certificates.crt", warn=tls_enabled),
    )

    c = r.section(data, "client", "client")
    r.check_keys(c, ("id", "buffer", "last_will", "clean_session", "keep_alive_interval", "max_inflight",
                     "max_packet_size", "tls"), "client")
    cbuf = r.section(c, "buffer", "client/buffer")
    r.check_keys(cbuf, ("size", "directory", "max_age"), "client/buffer")
    will = r.section(c, "last_will", "client/last_will")
    r.check_keys(will, ("topic", "message", "qos", "retained"), "client/last_will")
    ctls = r.section(c, "tls", "client/tls")
    unsupported = [k for k in ("version", "verify", "alpn_protos") if k in ctls]
    if unsupported:
        raise r.fail(f"client/tls/{unsupported[0]}",
                     "(mqtt_client 2.x) is not supported: micros_rt negotiates the highest TLS version both sides "
                     "support, always verifies the broker's certificate and host name against 'broker/tls/ca_certificate' and "
                     "sends no ALPN protocols; remove the key")
    r.check_keys(ctls, ("certificate", "key", "password"), "client/tls")
    client_id = r.get(c, "id", "client/id", str, "")
    if not client_id:
        r.warnings.append("Client buffer can not be enabled when client ID is empty")
    will_topic = r.get(will, "topic", "client/last_will/topic", str, "", warn=False)
    client = ClientParams(
        id=client_id,
        buffer_size=r.get(cbuf, "size", "client/buffer/size", int, 0, warn=bool(client_id), lo=0, hi=10_000_000),
        buffer_directory=r.get(cbuf, "directory", "client/buffer/directory", str, "buffer", warn=bool(client_id)),
        buffer_max_age=r.get(cbuf, "max_age", "client/buffer/max_age", float, 0.0, warn=False, lo=0, hi=1e9),
        last_will_topic=will_topic,
        last_will_message=r.get(will, "message", "client/last_will/message", str, "offline", warn=bool(will_topic)),
        last_will_qos=r.get(will, "qos", "client/last_will/qos", int, 0, warn=bool(will_topic), lo=0, hi=2),
        last_will_retained=r.get(will, "retained", "client/last_will/retained", bool, False, warn=bool(will_topic)),
        clean_session=r.get(c, "clean_session", "client/clean_session", bool, True),
        keep_alive_interval=r.get(c, "keep_alive_interval", "client/keep_alive_interval", float, 60.0,
                                  lo=0, hi=65535),
        max_inflight=r.get(c, "max_inflight", "client/max_inflight", int, 65535, lo=1, hi=65535),
        max_packet_size=r.get(c, "max_packet_size", "client/max_packet_size", int, 0, warn=False, lo=0,
                              hi=268435455),
        tls_certificate=r.get(ctls, "certificate", "client/tls/certificate", str, "", warn=False),
        tls_key=r.get(ctls, "key", "client/tls/key", str, "", warn=False),
        tls_password=r.get(ctls, "password", "client/tls/password", str, "", warn=False),
    )
    if bool(client.tls_certificate) != bool(client.tls_key):
        raise r.fail("client/tls/key" if client.tls_certificate else "client/tls/certificate",
                     "must be given together with the other of 'client/tls/certificate' and 'client/tls/key'")
    if client.buffer_size > 0 and not client.id:
        raise r.fail("client/buffer/size", "needs 'client/id': mqtt_client buffers only for a named client")
    return broker, client


def parse_params(data: Any, *, source: str = "params") -> Tuple[MqttParams, List[str]]:
    """Validate a parsed YAML document; return the parameters and mqtt_client's default warnings."""
    r = _Reader(source)
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


def parse_wire(r: "_Reader", data: Mapping[str, Any], name: str) -> WireGeneration:
    """``mqtt_client_version``: 2 (default) or 1, also written '2.x'/'1.x'."""
    value = data.get("mqtt_client_version")
    if value is None:
        return WireGeneration.V2
    text = str(value).strip().lower()
    for wire in WireGeneration:
        if not isinstance(value, bool) and text in (str(int(wire)), wire.label, f"{int(wire)}.0"):
            return wire
    raise r.fail(name, f"is {value!r}: the mqtt_client wire to write, 2 (mqtt_client 2.0-2.3, the ROS 1 releases "
                       "installed today; the default) or 1 (mqtt_client 1.0-1.1)")


def _entries(r: _Reader, bridge: Mapping[str, Any], key: str) -> List[Mapping[str, Any]]:
    value = bridge.get(key)
    if value is None:
        return []
    if not isinstance(value, list) or not all(isinstance(e, Mapping) for e in value):
        raise r.fail(f"bridge/{key}", f"must be a list of mappings, got {value!r}")
    return value


def _topic(r: _Reader, data: Mapping[str, Any], key: str, name: str) -> str:
    value = r.get(data, key, f"{name}/{key}", str)
    if not value:
        raise r.fail(f"{name}/{key}", "is required (a non-empty topic name)")
    if key == "mqtt_topic" and any(ch in value for ch in "+#"):
        raise r.fail(f"{name}/{key}", f"is {value!r}: MQTT wildcards '+' and '#' cannot name one ROS topic")
    return str(value)


def _advanced(r: _Reader, e: Mapping[str, Any], name: str, ros_keys: Sequence[str],
              mqtt_keys: Sequence[str]) -> Tuple[Mapping[str, Any], Mapping[str, Any]]:
    """An entry's ``advanced.ros`` and ``advanced.mqtt`` sections, their keys checked."""
    adv = r.section(e, "advanced", f"{name}/advanced")
    r.check_keys(adv, ("ros", "mqtt"), f"{name}/advanced")
    ros = r.section(adv, "ros", f"{name}/advanced/ros")
    r.check_keys(ros, ros_keys, f"{name}/advanced/ros")
    mqtt = r.section(adv, "mqtt", f"{name}/advanced/mqtt")
    r.check_keys(mqtt, mqtt_keys, f"{name}/advanced/mqtt")
    return ros, mqtt


def _ros2mqtt(r: _Reader, e: Mapping[str, Any], k: int) -> Ros2MqttParams:
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


def _mqtt2ros(r: _Reader, e: Mapping[str, Any], k: int) -> Mqtt2RosParams:
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


def _no_duplicates(r: _Reader, names: List[str], section: str, key: str) -> None:
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


def resolve_path(path: str, *, env: Optional[Dict[str, str]] = None) -> str:
    """mqtt_client's rule: a relative path is relative to ``ROS_HOME`` (the working directory if unset)."""
    if not path or os.path.isabs(path):
        return path
    environ = os.environ if env is None else env
    return os.path.join(environ.get("ROS_HOME") or os.getcwd(), path)
