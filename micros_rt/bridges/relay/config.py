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
"""

from __future__ import annotations

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
from ...qos.yamlconfig import (compose, expect_mapping, is_null, location, mapping_items, node_value, parse_qos_options,
                               sub_mapping)

__all__ = ["ExportRule", "ImportRule", "RelayConfig", "RelayConfigError", "ServiceImport", "load_config",
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
class RelayConfig:
    graph: str
    exports: Tuple[ExportRule, ...]
    imports: Tuple[ImportRule, ...]
    source: str = "<string>"
    export_services: Tuple[str, ...] = ()
    import_services: Tuple[ServiceImport, ...] = ()
    link_bandwidth: Optional[float] = None   #: bits per second of the link the exports cross, if given

    def outside_name(self, topic: str) -> str:
        """The name an exported ``topic`` has outside this graph: ``/<graph><topic>``."""
        return f"/{self.graph}{topic}"


def load_config(path: str) -> RelayConfig:
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as exc:
        raise RelayConfigError(f"{path}: cannot read the relay configuration: {exc}") from None
    return parse_config(text, source=os.fspath(path))


def parse_config(text: str, *, source: str = "<string>") -> RelayConfig:
    """Parse relay YAML ``text``; ``source`` names it in errors."""
    try:
        root = compose(text, source=source)
    except MicrosRtError as exc:
        raise RelayConfigError(str(exc)) from None
    if root is None:
        raise RelayConfigError(f"{source}: empty relay configuration; it needs at least 'graph:'")
    try:
        return _parse(root, source)
    except MicrosRtError as exc:  # a ProfileError from the shared option parser: same one-line form
        if isinstance(exc, RelayConfigError):
            raise
        raise RelayConfigError(str(exc)) from None


def _parse(root: yaml.Node, source: str) -> RelayConfig:
    expect_mapping(root, source, "the top level", "a mapping with 'graph', 'export' and 'import'")
    graph: Optional[str] = None
    exports: List[ExportRule] = []
    imports: List[ImportRule] = []
    import_nodes: List[Tuple[yaml.ScalarNode, yaml.Node]] = []
    export_services: List[str] = []
    service_nodes: List[Tuple[yaml.ScalarNode, yaml.Node]] = []
    link_bandwidth: Optional[float] = None
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
        else:
            raise RelayConfigError(f"{location(source, key_node)}: unknown key {key!r}; expected 'graph', 'export', "
                                   f"'import', 'export_services', 'import_services', 'link_bandwidth'")
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
    return RelayConfig(graph, tuple(exports), tuple(imports), source, tuple(export_services), services,
                       link_bandwidth)


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
    local = outside
    if "as" in mine:
        node, value = mine["as"]
        if not isinstance(value, str) or not _TOPIC_NAME.match(value):
            raise RelayConfigError(f"{location(source, node)}: {path}.as: {value!r} is invalid: expected a global "
                                   f"service name")
        local = value
    timeout = 10.0
    if "timeout" in mine:
        node, value = mine["timeout"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise RelayConfigError(f"{location(source, node)}: {path}.timeout: {value!r} is invalid: expected "
                                   f"seconds, a number above 0")
        timeout = float(value)
    return ServiceImport(outside, local, outside.split("/")[1], timeout)


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
    max_rate = math.inf
    if "max_rate" in mine:
        node, value = mine["max_rate"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise RelayConfigError(f"{location(source, node)}: {path}.max_rate: {value!r} is invalid: expected "
                                   f"messages per second, a number above 0")
        max_rate = float(value)
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
    local = outside
    if "as" in mine:
        node, value = mine["as"]
        if not isinstance(value, str) or not _TOPIC_NAME.match(value):
            raise RelayConfigError(f"{location(source, node)}: {path}.as: {value!r} is invalid: expected a global "
                                   f"topic name (e.g. /others/chatter)")
        local = value
    options = None if is_null(qos_node) or not qos_node.value else parse_qos_options(SubscribeQoSOptions, qos_node, source, path)
    return ImportRule(outside, local, origin, options, _queue_size(mine, source, path),
                      _flag(mine, "latch", source, path))
