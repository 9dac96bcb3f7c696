"""The relay's configuration file (YAML), parsed with line numbers: every error is one line naming the file,
the line and the key.

::

    graph: robot_a                    # this graph's name outside it: exports are /robot_a/<topic>
    export:                           # topics of this graph, whoever publishes them
      /chatter: {transport_priority: HIGH}
      /camera/image: {using_best_effort_protocol: true, max_rate: 5}
      /map: {latch: true}             # late joiners on other robots get the last message
      /sensors/*: {}                  # globs and ^regex$ as in QoS profiles
    import:                           # topics other graphs export, published in this graph
      /robot_b/chatter: {}            # under the same name
      /robot_b/odom: {as: /others/odom, deadline: 0.5}
    export_services: [/add_two_ints]  # this graph's services other graphs may call
    import_services:                  # other graphs' services, offered in this graph
      /robot_b/add_two_ints: {timeout: 5, as: /b/add_two_ints}
    link_bandwidth: 40Mbit            # the slow link the exports cross (optional; see below)
    ros2:                             # between this graph and ROS 2 (same DDS domain), names unchanged
      export: {/chatter: {}, /set_flag: {}}          # ROS 1 topics or services, offered to ROS 2
      import: {/ros2_chatter: {}, /ros2_trigger: {as: /trigger}}   # ROS 2 ones, offered in this graph

An export's options are :class:`~micros_rt.AdvertiseQoSOptions` keys (the DDS writer's QoS on the link) plus
``max_rate`` (Hz, applied before the link: newer messages within 1/max_rate of the last one sent are not
sent, counted), ``queue_size`` (the writer's history; null: lossless) and ``latch``. An import's options are
:class:`~micros_rt.SubscribeQoSOptions` keys (deadline, time filter, ...) plus ``as``, ``queue_size`` and
``latch``. Option values are checked as in a QoS profile (:mod:`micros_rt.qos.yamlconfig`).

``link_bandwidth`` (bits per second, ``40Mbit`` as in a profile's ``links``) is the rate of the link the
exports cross. The relay process that carries only exports below HIGH then asks for a small UDP send buffer
(:func:`send_buffer_for`): what it has queued in the link never exceeds about twice that, so HIGH exports
(another process, another socket) wait at most a few milliseconds behind it on a link that does not honour
DSCP.

``ros2:`` entries (:class:`Ros2Entry`) name a topic, a service or an action, which the relay finds out at run
time (see :mod:`.ros2`). An ``export`` entry takes the export options above plus ``as`` (its ROS 2 name) and
``timeout`` (seconds a service call may take, or the other side may take to accept a goal); an ``import`` entry
the import options plus ``timeout``. ``latch`` left out
follows the other side (a latching ROS 1 publisher, a transient_local ROS 2 writer).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import yaml

from ...exceptions import MicrosRtError
from ...qos import AdvertiseQoSOptions, SubscribeQoSOptions
from ...qos.links import parse_bandwidth, send_buffer_for
from ...qos.topic_rules import TopicPattern
from ...qos.yamlconfig import (expect_mapping, is_null, load_document, location, mapping_items, node_value,
                               parse_document, parse_qos_options, sub_mapping)

__all__ = ["ExportRule", "ImportRule", "RelayConfig", "RelayConfigError", "Ros2Entry", "ServiceImport", "load_config",
           "parse_config", "send_buffer_for"]

_GRAPH_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_TOPIC_NAME = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")
DEFAULT_QUEUE_SIZE = 10


class RelayConfigError(MicrosRtError, ValueError):
    """A relay configuration that cannot be used; the message names file, line and key."""


@dataclass(frozen=True)
class ExportRule:
    key: str                              # topic name, glob or ^regex$
    options: AdvertiseQoSOptions
    max_rate: float = math.inf            # Hz
    queue_size: Optional[int] = DEFAULT_QUEUE_SIZE
    latch: bool = False
    pattern: TopicPattern = field(default_factory=lambda: TopicPattern.parse("/"), compare=False)


@dataclass(frozen=True)
class ImportRule:
    outside: str                          # /<graph>/<topic>, as the exporting relay names it
    local: str                            # the name it is published under in this graph
    origin: str                           # the exporting graph
    options: Optional[SubscribeQoSOptions]
    queue_size: Optional[int] = DEFAULT_QUEUE_SIZE
    latch: bool = False


@dataclass(frozen=True)
class ServiceImport:
    outside: str                          # /<graph>/<service>
    local: str
    origin: str
    timeout: float = 10.0                 # seconds a forwarded call may take


@dataclass(frozen=True)
class Ros2Entry:
    """One entry of the ``ros2:`` section: a topic or a service (decided at run time) carried one way between
    this graph and ROS 2."""

    direction: str                        # "export" (ROS 1 -> ROS 2) or "import" (ROS 2 -> ROS 1)
    name: str                             # the key: a ROS 1 name (export) or a ROS 2 name (import)
    target: str                           # its name on the other side (``as``, else the same)
    where: str                            # <file>:<line> of the key, for messages at run time
    export_options: AdvertiseQoSOptions = field(default_factory=AdvertiseQoSOptions)
    import_options: Optional[SubscribeQoSOptions] = None
    max_rate: float = math.inf
    queue_size: Optional[int] = DEFAULT_QUEUE_SIZE
    latch: Optional[bool] = None          # None: as the other side's publisher/writer is
    timeout: float = 10.0                 # seconds a forwarded service call may take
    topic_keys: Tuple[str, ...] = ()      # options given that only a topic has (said when it is a service)

    @property
    def ros1_name(self) -> str:
        return self.name if self.direction == "export" else self.target

    @property
    def ros2_name(self) -> str:
        return self.target if self.direction == "export" else self.name


@dataclass(frozen=True)
class RelayConfig:
    graph: str
    exports: Tuple[ExportRule, ...]
    imports: Tuple[ImportRule, ...]
    source: str = "<string>"
    export_services: Tuple[str, ...] = ()
    import_services: Tuple[ServiceImport, ...] = ()
    link_bandwidth: Optional[float] = None   #: bits per second of the link the exports cross, if given
    ros2: Tuple[Ros2Entry, ...] = ()         #: the ``ros2:`` section's entries, exports first

    def outside_name(self, topic: str) -> str:
        """The name an exported ``topic`` has outside this graph: ``/<graph><topic>``."""
        return f"/{self.graph}{topic}"


_EMPTY = "empty relay configuration; it needs at least 'graph:'"


def load_config(path: str | os.PathLike[str]) -> RelayConfig:
    """Read a relay configuration file; errors are :class:`RelayConfigError` naming file, line, key."""
    return load_document(path, _parse, what="the relay configuration", empty=_EMPTY, error=RelayConfigError)


def parse_config(text: str, *, source: str = "<string>") -> RelayConfig:
    """Parse relay YAML ``text``; ``source`` names it in errors."""
    return parse_document(text, _parse, source=source, empty=_EMPTY, error=RelayConfigError)


def _parse(root: yaml.Node, source: str) -> RelayConfig:
    expect_mapping(root, source, "the top level", "a mapping with 'graph', 'export' and 'import'")
    graph: Optional[str] = None
    exports: List[ExportRule] = []
    imports: List[ImportRule] = []
    import_nodes: List[Tuple[yaml.ScalarNode, yaml.Node]] = []
    export_services: List[str] = []
    service_nodes: List[Tuple[yaml.ScalarNode, yaml.Node]] = []
    link_bandwidth: Optional[float] = None
    ros2_node: Optional[yaml.Node] = None
    for key_node, body in mapping_items(root, source, ""):
        key = key_node.value
        if key == "graph":
            value = node_value(body) if isinstance(body, yaml.ScalarNode) else None
            if not isinstance(value, str) or not _GRAPH_NAME.match(value):
                raise RelayConfigError(f"{location(source, body)}: graph: {value!r} is invalid: expected a name "
                                       f"(a letter, then letters, digits, '_'), e.g. robot_a")
            graph = value
        elif key == "export":
            if not is_null(body):
                expect_mapping(body, source, "export", "a mapping of topic names/patterns to options")
                exports = [_export(k, v, source) for k, v in mapping_items(body, source, "export")]
        elif key == "import":
            if not is_null(body):
                expect_mapping(body, source, "import", "a mapping of outside topic names to options")
                import_nodes = mapping_items(body, source, "import")
        elif key == "export_services":
            export_services = _service_names(body, source)
        elif key == "import_services":
            if not is_null(body):
                expect_mapping(body, source, "import_services", "a mapping of outside service names to options")
                service_nodes = mapping_items(body, source, "import_services")
        elif key == "link_bandwidth":
            try:
                link_bandwidth = parse_bandwidth(node_value(body) if isinstance(body, yaml.ScalarNode) else body)
            except ValueError as exc:
                raise RelayConfigError(f"{location(source, body)}: link_bandwidth: {exc}") from None
        elif key == "ros2":
            ros2_node = body
        else:
            raise RelayConfigError(f"{location(source, key_node)}: unknown key {key!r}; expected 'graph', 'export', "
                                   f"'import', 'export_services', 'import_services', 'link_bandwidth', 'ros2'")
    if graph is None:
        raise RelayConfigError(f"{source}:1: graph: missing; name this graph (e.g. 'graph: robot_a'): exported "
                               f"topics are /<graph>/<topic> outside it")
    imports = [_import(k, v, source, graph) for k, v in import_nodes]
    for out in exports:
        for incoming in imports:
            if out.pattern.exact and out.key == incoming.local:
                raise RelayConfigError(f"{source}: export: {out.key} is what this relay imports from "
                                       f"{incoming.origin} ({incoming.outside}): a topic is never sent back out")
    locals_seen: Dict[str, str] = {}
    for incoming in imports:
        if incoming.local in locals_seen:
            raise RelayConfigError(f"{source}: import: {incoming.outside} and {locals_seen[incoming.local]} are "
                                   f"both published as {incoming.local}")
        locals_seen[incoming.local] = incoming.outside
    services = tuple(_service_import(k, v, source, graph) for k, v in service_nodes)
    ros2 = _ros2_section(ros2_node, source) if ros2_node is not None else ()
    for entry in ros2:
        if entry.direction == "import" and entry.ros1_name in locals_seen:
            raise RelayConfigError(f"{entry.where}: ros2.import[{entry.name!r}]: {entry.ros1_name} is also what "
                                   f"the import of {locals_seen[entry.ros1_name]} publishes in this graph; give one "
                                   f"another name with 'as:'")
    return RelayConfig(graph, tuple(exports), tuple(imports), source, tuple(export_services), services,
                       link_bandwidth, ros2)


_ROS2_EXPORT_KEYS = ("as", "max_rate", "queue_size", "latch", "timeout")
_ROS2_IMPORT_KEYS = ("as", "queue_size", "latch", "timeout")


def _ros2_section(node: yaml.Node, source: str) -> Tuple[Ros2Entry, ...]:
    if is_null(node):
        return ()
    expect_mapping(node, source, "ros2", "a mapping with 'export' and/or 'import'")
    entries: List[Ros2Entry] = []
    for key_node, body in mapping_items(node, source, "ros2"):
        direction = key_node.value
        if direction not in ("export", "import"):
            raise RelayConfigError(f"{location(source, key_node)}: ros2.{direction}: unknown key; expected 'export' "
                                   f"(ROS 1 topics and services offered to ROS 2) or 'import' (ROS 2 ones offered "
                                   f"in this graph)")
        if is_null(body):
            continue
        expect_mapping(body, source, f"ros2.{direction}", "a mapping of topic or service names to options")
        entries += [_ros2_entry(direction, k, v, source) for k, v in mapping_items(body, source, f"ros2.{direction}")]
    entries.sort(key=lambda e: e.direction != "export")
    seen: Dict[Tuple[str, str], Ros2Entry] = {}
    for entry in entries:
        for side, name in (("ROS 1", entry.ros1_name), ("ROS 2", entry.ros2_name)):
            other = seen.get((side, name))
            if other is not None:
                raise RelayConfigError(f"{entry.where}: ros2.{entry.direction}[{entry.name!r}]: {name} ({side} side) "
                                       f"is also the name of ros2.{other.direction}[{other.name!r}] ({other.where}); a "
                                       f"name is carried one way only, so nothing goes back where it came from")
            seen[(side, name)] = entry
    return tuple(entries)


def _ros2_entry(direction: str, key_node: yaml.ScalarNode, body: yaml.Node, source: str) -> Ros2Entry:
    name = key_node.value
    path = f"ros2.{direction}[{name!r}]"
    where = location(source, key_node)
    if not isinstance(name, str) or not _TOPIC_NAME.match(name):
        raise RelayConfigError(f"{where}: ros2.{direction}: {name!r} is not a global topic or service name (e.g. "
                               f"/chatter); globs are not accepted here")
    own = _ROS2_EXPORT_KEYS if direction == "export" else _ROS2_IMPORT_KEYS
    mine, qos_node = _split(body, source, path, own)
    target = _name_as(mine, source, path, name, "name (e.g. /robot/chatter)")
    timeout = _above_zero(mine, "timeout", source, path, 10.0, "seconds")
    latch: Optional[bool] = _flag(mine, "latch", source, path) if "latch" in mine else None
    given = [k.value for k, _v in qos_node.value] if isinstance(qos_node, yaml.MappingNode) else []
    topic_keys = tuple(k for k in ("max_rate", "queue_size", "latch") if k in mine) + tuple(given)
    if direction == "export":
        max_rate = _above_zero(mine, "max_rate", source, path, math.inf, "messages per second")
        options = parse_qos_options(AdvertiseQoSOptions, qos_node, source, path)
        return Ros2Entry("export", name, target, where, export_options=options, max_rate=max_rate,
                         queue_size=_queue_size(mine, source, path), latch=latch, timeout=timeout,
                         topic_keys=topic_keys)
    sub: Optional[SubscribeQoSOptions] = None
    if given:
        sub = parse_qos_options(SubscribeQoSOptions, qos_node, source, path)
        if "ordered_by_sending_timestamp" not in given:
            # ROS 2 writers offer BY_RECEPTION_TIMESTAMP: a BY_SOURCE reader would never match them
            sub = dataclasses.replace(sub, ordered_by_sending_timestamp=False)
    return Ros2Entry("import", name, target, where, import_options=sub, queue_size=_queue_size(mine, source, path),
                     latch=latch, timeout=timeout, topic_keys=topic_keys)


def _service_names(node: yaml.Node, source: str) -> List[str]:
    if is_null(node):
        return []
    if not isinstance(node, yaml.SequenceNode):
        raise RelayConfigError(f"{location(source, node)}: export_services: expected a list of service names "
                               f"(e.g. [/add_two_ints])")
    names = []
    for item in node.value:
        value = node_value(item) if isinstance(item, yaml.ScalarNode) else None
        if not isinstance(value, str) or not _TOPIC_NAME.match(value):
            raise RelayConfigError(f"{location(source, item)}: export_services: {value!r} is not a global service "
                                   f"name (e.g. /add_two_ints)")
        names.append(value)
    return names


def _service_import(key_node: yaml.ScalarNode, body: yaml.Node, source: str, graph: str) -> ServiceImport:
    outside = key_node.value
    path = f"import_services[{outside!r}]"
    where = location(source, key_node)
    if not _TOPIC_NAME.match(outside) or outside.count("/") < 2 or outside.split("/")[1] == graph:
        raise RelayConfigError(f"{where}: import_services: {outside!r} is invalid: expected /<other graph>/<service> "
                               f"as the exporting relay names it")
    mine, rest = _split(body, source, path, ("as", "timeout"))
    if isinstance(rest, yaml.MappingNode) and rest.value:
        key = rest.value[0][0]
        raise RelayConfigError(f"{location(source, key)}: {path}.{key.value}: unknown option; known: as, timeout")
    local = _name_as(mine, source, path, outside, "service name")
    timeout = _above_zero(mine, "timeout", source, path, 10.0, "seconds")
    return ServiceImport(outside, local, outside.split("/")[1], timeout)


def _name_as(mine: Dict[str, Tuple[yaml.Node, Any]], source: str, path: str, default: str, what: str) -> str:
    """An entry's ``as:`` (a global name; ``what`` says which kind in the error), else ``default``."""
    if "as" not in mine:
        return default
    node, value = mine["as"]
    if not isinstance(value, str) or not _TOPIC_NAME.match(value):
        raise RelayConfigError(f"{location(source, node)}: {path}.as: {value!r} is invalid: expected a global {what}")
    return value


def _above_zero(mine: Dict[str, Tuple[yaml.Node, Any]], key: str, source: str, path: str, default: float,
                unit: str) -> float:
    """An entry's ``key`` (a number above 0, in ``unit``), else ``default``."""
    if key not in mine:
        return default
    node, value = mine[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise RelayConfigError(f"{location(source, node)}: {path}.{key}: {value!r} is invalid: expected {unit}, a "
                               f"number above 0")
    return float(value)


def _split(node: yaml.Node, source: str, path: str, own: Tuple[str, ...]) -> Tuple[Dict[str, Tuple[yaml.Node, Any]],
                                                                                yaml.Node]:
    """The relay's own keys (``own``) of an options mapping, and a mapping node with the QoS keys left."""
    if is_null(node):
        return {}, node
    expect_mapping(node, source, path, "a mapping of option names to values")
    mine: Dict[str, Tuple[yaml.Node, Any]] = {}
    rest: List[Tuple[yaml.Node, yaml.Node]] = []
    for key_node, value_node in mapping_items(node, source, path):
        if key_node.value in own:
            mine[key_node.value] = (value_node, node_value(value_node) if isinstance(value_node, yaml.ScalarNode)
                                    else None)
        else:
            rest.append((key_node, value_node))
    return mine, sub_mapping(node, rest)


def _queue_size(mine: Dict[str, Tuple[yaml.Node, Any]], source: str, path: str) -> Optional[int]:
    if "queue_size" not in mine:
        return DEFAULT_QUEUE_SIZE
    node, value = mine["queue_size"]
    if value is None and is_null(node):
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise RelayConfigError(f"{location(source, node)}: {path}.queue_size: {value!r} is invalid: expected a "
                               f"positive integer, or null for lossless")
    return value


def _flag(mine: Dict[str, Tuple[yaml.Node, Any]], key: str, source: str, path: str) -> bool:
    if key not in mine:
        return False
    node, value = mine[key]
    if not isinstance(value, bool):
        raise RelayConfigError(f"{location(source, node)}: {path}.{key}: {value!r} is invalid: expected true or false")
    return value


def _export(key_node: yaml.ScalarNode, body: yaml.Node, source: str) -> ExportRule:
    key = key_node.value
    path = f"export[{key!r}]"
    try:
        pattern = TopicPattern.parse(key)
    except re.error as exc:
        raise RelayConfigError(f"{location(source, key_node)}: export: key {key!r} is not a valid regular "
                               f"expression: {exc}") from None
    if pattern.exact and not _TOPIC_NAME.match(key):
        raise RelayConfigError(f"{location(source, key_node)}: export: {key!r} is not a global topic name "
                               f"(e.g. /camera/image)")
    mine, qos_node = _split(body, source, path, ("max_rate", "queue_size", "latch"))
    max_rate = _above_zero(mine, "max_rate", source, path, math.inf, "messages per second")
    options = parse_qos_options(AdvertiseQoSOptions, qos_node, source, path)
    return ExportRule(key, options, max_rate, _queue_size(mine, source, path), _flag(mine, "latch", source, path),
                      pattern)


def _import(key_node: yaml.ScalarNode, body: yaml.Node, source: str, graph: str) -> ImportRule:
    outside = key_node.value
    path = f"import[{outside!r}]"
    where = location(source, key_node)
    if not _TOPIC_NAME.match(outside) or outside.count("/") < 2:
        raise RelayConfigError(f"{where}: import: {outside!r} is invalid: expected /<graph>/<topic> as the "
                               f"exporting relay names it (e.g. /robot_a/chatter)")
    origin = outside.split("/")[1]
    if origin == graph:
        raise RelayConfigError(f"{where}: import: {outside!r} is this graph's own export ({graph}): a topic never "
                               f"comes back to the graph it left")
    mine, qos_node = _split(body, source, path, ("as", "queue_size", "latch"))
    local = _name_as(mine, source, path, outside, "topic name (e.g. /others/chatter)")
    options = None if is_null(qos_node) or not qos_node.value else parse_qos_options(SubscribeQoSOptions, qos_node, source, path)
    return ImportRule(outside, local, origin, options, _queue_size(mine, source, path),
                      _flag(mine, "latch", source, path))
