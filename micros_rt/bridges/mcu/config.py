"""The bridge's YAML configuration: what goes to and comes from the microcontroller.

::

    microcontroller: {address: 127.0.0.2, topic_port: 20000, service_port: 20001}   # the board
    bind: {address: 127.0.0.1, topic_port: 20000, service_port: 20001}              # the bridge
    mtu: 1472                                    # payload bytes per datagram
    wire_form: mid2015                           # optional: what is written (every form is read): final
                                                 # (CVRA's last cvra_rpc; also "cvra"), mid2015, readme, map;
                                                 # unset: the era the board's own datagrams and requests show
    stats_period: 1.0                            # seconds between ~stats messages
    to_microcontroller:                          # ROS topics sent to the board
      - {topic: /cmd_vel, type: geometry_msgs/Twist, qos: {time_filter_duration: 0.05}}
    from_microcontroller:                        # datagrams from the board, published on ROS topics
      - {topic: /imu, type: sensor_msgs/Imu, name: imu, qos: {deadline: 0.5}}
    services_on_microcontroller:                 # served by the board, offered as ROS services
      - {service: /mcu/reset, type: std_srvs/Trigger, name: reset, timeout: 2.0}
    services_for_microcontroller:                # ROS services the board may call through the bridge
      - {service: /set_mode, type: std_srvs/SetBool, name: set_mode}

Every error (:class:`~micros_rt.transports.mcu.errors.McuConfigError`) names the file, the line and the key.
``qos:`` values are parsed and validated exactly as in a YAML QoS profile (:mod:`micros_rt.qos.yamlconfig`).
The result is the link's :class:`~micros_rt.transports.mcu.spec.McuConfig`, which
:class:`~micros_rt.transports.mcu.link.McuLink` takes.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import math
import os
from typing import Any, Callable, Dict, List, Optional, Tuple

import roslib.message
import rosgraph.names
import yaml

from micros_rt.qos.options import MCU_FROM, MCU_SERVICE, MCU_TO, OPTIONS, AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.qos.yamlconfig import (describe_node, expect_mapping, is_null, load_document, location, mapping_items,
                                      node_value, parse_document, parse_qos_options, sub_mapping)
from micros_rt.transports.mcu.errors import McuConfigError
from micros_rt.transports.mcu.spec import (DEFAULT_SERVICE_TIMEOUT, MAX_MTU, Address, McuConfig, ServiceEntry,
                                           TopicEntry)
from micros_rt.transports.mcu.wire import WIRE_FORM_NAMES, WireForm

__all__ = ["load_config", "parse_config"]


def _applying(where: str) -> Tuple[str, ...]:
    """The QoS keys that have an effect on one kind of entry (the catalogue's ``applies``), once each."""
    return tuple(dict.fromkeys(o.name for o in OPTIONS if where in o.applies))


#: qos keys each kind of entry understands (from the QoS catalogue, micros_rt.qos.options.OPTIONS)
_TO_QOS = _applying(MCU_TO)
_FROM_QOS = _applying(MCU_FROM)
_SERVICE_QOS = _applying(MCU_SERVICE)
#: the publisher-only keys go to the publishing side's options, the rest to the subscribing side's
_ADVERTISE_KEYS = tuple(k for k in AdvertiseQoSOptions._KEYS if k not in SubscribeQoSOptions._KEYS)


_EMPTY = "empty configuration; at least 'microcontroller: {address: ...}' is needed"


def load_config(path: str | os.PathLike[str]) -> McuConfig:
    """Read a bridge configuration file; errors are :class:`McuConfigError` naming file, line, key."""
    return load_document(path, _parse, what="the bridge configuration", empty=_EMPTY, error=McuConfigError)


def parse_config(text: str, *, source: str = "<string>") -> McuConfig:
    """Parse configuration YAML ``text``; ``source`` names it in error messages."""
    return parse_document(text, _parse, source=source, empty=_EMPTY, error=McuConfigError)


def _parse(root: yaml.Node, source: str) -> McuConfig:
    return _Parser(source).parse(root)


class _Parser:
    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, node: yaml.Node, path: str, words: str) -> McuConfigError:
        return McuConfigError(f"{location(self.source, node)}: {path}: {words}")

    def parse(self, root: yaml.Node) -> McuConfig:
        expect_mapping(root, self.source, "the top level", "a mapping")
        known = ("microcontroller", "bind", "mtu", "stats_period", "wire_form", "to_microcontroller", "from_microcontroller",
                 "services_on_microcontroller", "services_for_microcontroller")
        values: Dict[str, Any] = {"source": self.source}
        board: Optional[Address] = None
        for key_node, node in mapping_items(root, self.source, ""):
            key = key_node.value
            if key not in known:
                raise self.error(key_node, key, f"unknown key; known keys: {', '.join(known)}")
            if key == "microcontroller":
                board = self.address(node, key, required_address=True)
            elif key == "bind":
                values[key] = self.address(node, key, required_address=False)
            elif key == "mtu":
                values[key] = self.integer(node, key, 8, MAX_MTU)
            elif key == "stats_period":
                values[key] = self.seconds(node, key)
            elif key == "wire_form":
                values[key] = self.wire_form(node, key)
            elif key in ("to_microcontroller", "from_microcontroller"):
                values[key] = self.topics(node, key)
            else:
                values[key] = self.services(node, key)
        if board is None:
            raise McuConfigError(f"{self.source}:{root.start_mark.line + 1}: microcontroller: missing; say where "
                                 f"the board is, e.g. 'microcontroller: {{address: 192.168.1.20}}'")
        bind = values.get("bind", Address("0.0.0.0"))
        if bind.family_v6 != board.family_v6:
            raise McuConfigError(f"{self.source}: bind.address {bind.address} and microcontroller.address "
                                 f"{board.address} must both be IPv4 or both IPv6")
        return McuConfig(microcontroller=board, **values)

    # -- scalars
    def scalar(self, node: yaml.Node, path: str) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            raise self.error(node, path, f"expected a single value, got {describe_node(node)}")
        return node_value(node)

    def integer(self, node: yaml.Node, path: str, lo: int, hi: int) -> int:
        value = self.scalar(node, path)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise self.error(node, path, f"{value!r} is invalid: expected an integer {lo}..{hi}")
        return value

    def seconds(self, node: yaml.Node, path: str) -> float:
        value = self.scalar(node, path)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
            raise self.error(node, path, f"{value!r} is invalid: expected a duration > 0 in seconds")
        return float(value)

    def text(self, node: yaml.Node, path: str) -> str:
        value = self.scalar(node, path)
        if not isinstance(value, str) or not value.strip():
            raise self.error(node, path, f"{value!r} is invalid: expected a non-empty string")
        return value.strip()

    def wire_form(self, node: yaml.Node, path: str) -> WireForm:
        value = self.scalar(node, path)
        form = WIRE_FORM_NAMES.get(value.strip().lower()) if isinstance(value, str) else None
        if form is not None:
            return form
        raise self.error(node, path, f"{value!r} is invalid: expected the form the board's firmware speaks -- "
                                     f"final (CVRA's last cvra_rpc, cvra/robot-software babf2cfa: [name, args] with "
                                     f"args nil, one bare value or a list in field order; also "
                                     f"'cvra' or 'babf2cfa'), mid2015 (CVRA's feb95469: [name, field1, ...]; also "
                                     f"'feb95469'), readme (the seed README, 0670b782: the name then a map of "
                                     f"fields, two objects; also '0670b782') or map ([name, {{fields}}], what "
                                     f"micros_rt wrote as 'cvra' before). Every form is read whatever this says; "
                                     f"without wire_form the bridge writes the era the board's own datagrams and "
                                     f"requests show (final until it has sent any)")

    def address(self, node: yaml.Node, path: str, *, required_address: bool) -> Address:
        expect_mapping(node, self.source, path, "a mapping with address, topic_port, service_port")
        got: Dict[str, Any] = {}
        for key_node, value_node in mapping_items(node, self.source, path):
            key = key_node.value
            if key == "address":
                text = self.text(value_node, f"{path}.address")
                try:
                    ipaddress.ip_address(text)
                except ValueError:
                    raise self.error(value_node, f"{path}.address",
                                     f"{text!r} is invalid: expected an IP address such as 192.168.1.20 "
                                     f"(host names are not resolved)") from None
                got[key] = text
            elif key in ("topic_port", "service_port"):
                got[key] = self.integer(value_node, f"{path}.{key}", 1, 65535)
            else:
                raise self.error(key_node, f"{path}.{key}", "unknown key; known keys: address, topic_port, "
                                                            "service_port")
        if "address" not in got:
            if required_address:
                raise self.error(node, f"{path}.address", "missing; the board's IP address is required")
            got["address"] = "0.0.0.0"
        return Address(**got)

    # -- entries
    def entries(self, node: yaml.Node, path: str) -> List[Tuple[int, yaml.MappingNode]]:
        if is_null(node):
            return []
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(node, path, f"expected a list of entries, got {describe_node(node)}")
        out = []
        for i, item in enumerate(node.value):
            expect_mapping(item, self.source, f"{path}[{i}]", "a mapping")
            out.append((i, item))
        return out

    def fields(self, item: yaml.MappingNode, path: str, known: Tuple[str, ...],
               required: Tuple[str, ...]) -> Dict[str, Tuple[yaml.Node, yaml.Node]]:
        got: Dict[str, Tuple[yaml.Node, yaml.Node]] = {}
        for key_node, value_node in mapping_items(item, self.source, path):
            if key_node.value not in known:
                raise self.error(key_node, f"{path}.{key_node.value}", f"unknown key; known keys: {', '.join(known)}")
            got[key_node.value] = (key_node, value_node)
        for key in required:
            if key not in got:
                raise self.error(item, f"{path}.{key}", "missing")
        return got

    def unique(self, seen: Dict[str, int], value: str, node: yaml.Node, path: str, what: str) -> None:
        if value in seen:
            raise self.error(node, path, f"{what} {value!r} is already used by the entry on line {seen[value]}")
        seen[value] = node.start_mark.line + 1

    def head(self, item: yaml.MappingNode, path: str, key: str, known: Tuple[str, ...], seen_ros: Dict[str, int],
             seen_names: Dict[str, int], what: str) -> Tuple[Dict[str, Tuple[yaml.Node, yaml.Node]], str, str, str]:
        """What topic and service entries share: the fields, the ROS name, the type and the wire name."""
        got = self.fields(item, path, known, (key, "type"))
        ros = self.ros_name(got[key][1], f"{path}.{key}")
        self.unique(seen_ros, ros, got[key][1], f"{path}.{key}", key)
        type_name = self.text(got["type"][1], f"{path}.type")
        name = self.text(got["name"][1], f"{path}.name") if "name" in got else type_name
        self.unique(seen_names, name, got["name"][1] if "name" in got else item, f"{path}.name", f"{what} name")
        return got, ros, type_name, name

    def resolve(self, node: yaml.Node, path: str, type_name: str, lookup: Callable[[str], Any], what: str,
                example: str) -> Any:
        found = lookup(type_name) if "/" in type_name else None
        if found is None:
            raise self.error(node, path, f"unknown {what} type {type_name!r}: expected 'package/Type' of an "
                                         f"installed package (e.g. {example})")
        return found

    def topics(self, node: yaml.Node, section: str) -> Tuple[TopicEntry, ...]:
        out: List[TopicEntry] = []
        names: Dict[str, int] = {}
        topics: Dict[str, int] = {}
        for i, item in self.entries(node, section):
            path = f"{section}[{i}]"
            got, topic, type_name, name = self.head(item, path, "topic", ("topic", "type", "name", "qos"), topics,
                                                    names, "stream")
            data_class = self.resolve(got["type"][1], f"{path}.type", type_name, roslib.message.get_message_class,
                                      "message", "geometry_msgs/Twist from Debian's python3-geometry-msgs")
            allowed = _TO_QOS if section == "to_microcontroller" else _FROM_QOS
            advertise, subscribe = self.qos(got.get("qos"), f"{path}.qos", allowed, section)
            out.append(TopicEntry(topic, type_name, name, data_class, advertise, subscribe, item.start_mark.line + 1))
        return tuple(out)

    def services(self, node: yaml.Node, section: str) -> Tuple[ServiceEntry, ...]:
        out: List[ServiceEntry] = []
        names: Dict[str, int] = {}
        services: Dict[str, int] = {}
        for i, item in self.entries(node, section):
            path = f"{section}[{i}]"
            got, service, type_name, name = self.head(item, path, "service",
                                                      ("service", "type", "name", "timeout", "qos"), services,
                                                      names, "service")
            service_class = self.resolve(got["type"][1], f"{path}.type", type_name,
                                         roslib.message.get_service_class, "service",
                                         "std_srvs/Trigger from Debian's python3-std-srvs")
            timeout = self.seconds(got["timeout"][1], f"{path}.timeout") if "timeout" in got \
                else DEFAULT_SERVICE_TIMEOUT
            advertise, _ = self.qos(got.get("qos"), f"{path}.qos", _SERVICE_QOS, section)
            out.append(ServiceEntry(service, type_name, name, service_class, timeout, advertise,
                                    item.start_mark.line + 1))
        return tuple(out)

    def ros_name(self, node: yaml.Node, path: str) -> str:
        value = self.text(node, path)
        if not rosgraph.names.is_legal_name(value) or value in ("/", "~"):
            raise self.error(node, path, f"{value!r} is not a legal ROS name (letters, digits, '_' and '/', "
                                         f"e.g. /cmd_vel)")
        return value

    def qos(self, pair: Optional[Tuple[yaml.Node, yaml.Node]], path: str, allowed: Tuple[str, ...],
            section: str) -> Tuple[AdvertiseQoSOptions, SubscribeQoSOptions]:
        advertise, subscribe = AdvertiseQoSOptions(), SubscribeQoSOptions(using_best_effort_protocol=True)
        if pair is None or is_null(pair[1]):
            return advertise, subscribe
        node = pair[1]
        expect_mapping(node, self.source, path, "a mapping of QoS option names to values")
        adv_pairs: List[Tuple[yaml.Node, yaml.Node]] = []
        sub_pairs: List[Tuple[yaml.Node, yaml.Node]] = []
        for key_node, value_node in mapping_items(node, self.source, path):
            key = key_node.value
            known = key in AdvertiseQoSOptions._KEYS or key in SubscribeQoSOptions._KEYS or key == "deadline_cb"
            if key not in allowed:
                why = "does not apply to" if known else "is not a QoS option of"
                raise self.error(key_node, f"{path}.{key}", f"{why} {section} entries; allowed here: "
                                                            f"{', '.join(allowed)}")
            if key == "using_best_effort_protocol" and self.scalar(value_node, f"{path}.{key}") is False:
                raise self.error(value_node, f"{path}.{key}",
                                 "reliable delivery (false) cannot be given on the microcontroller link: it "
                                 "carries one UDP datagram per message, with no acknowledgement and no "
                                 "retransmission, so it is best effort only. Remove the option (or set it to "
                                 "true); for requests that must not be lost, use a service "
                                 "(services_on_microcontroller), which waits for the board's answer")
            (adv_pairs if key in _ADVERTISE_KEYS else sub_pairs).append((key_node, value_node))
        if adv_pairs:
            advertise = parse_qos_options(AdvertiseQoSOptions, sub_mapping(node, adv_pairs), self.source, path)
        if sub_pairs:
            parsed = parse_qos_options(SubscribeQoSOptions, sub_mapping(node, sub_pairs), self.source, path)
            subscribe = dataclasses.replace(parsed, using_best_effort_protocol=True)  # the link's only kind
        return advertise, subscribe


