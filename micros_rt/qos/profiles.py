"""YAML QoS profiles: per-topic QoS options kept out of the code.

Format::

    publishers:
      /chatter: {transport_priority: HIGH, latency_budget: 0.005}
      "/camera/*": {using_best_effort_protocol: true, msg_valid_period: 0.1}
      /debug/cloud: {transport_hints: [TCPROS]}
    subscribers:
      /chatter: {time_filter_duration: 1.0, deadline: 0.5}
      "/camera/*": {transport_hints: [TCPROS]}
    links:
      radio: {peers: [10.0.0.0/24], bandwidth: 40Mbit}

``links`` names links of limited bandwidth (:mod:`micros_rt.qos.links`): this node's TCPROS connections of
topics below HIGH to peers across one are paced below its rate, leaving room for HIGH topics.

``transport_hints`` of a subscriber lists the transports it offers, in order, as ``TransportHints`` in code
(which wins when it gives any). A publisher's lists the transports it serves: ``[TCPROS]`` keeps the topic off
DDS altogether (no DDS writer: every subscriber, micros_rt's too, gets TCPROS; ROS 2 nodes do not see it), so
the sending robot alone can put its camera on TCPROS across its radio (with ``links``, paced); TCPROS cannot be
left out (stock subscribers connect with nothing else). Across a constrained link a large LOW topic over
TCPROS leaves the link's queue to TCP's congestion window where DDS keeps it full, and a HIGH topic on DDS
stops waiting behind it (README, constrained link). ``[TCPROS]`` alone: with ``[TCPROS, DDS]`` the
subscriber's DDS reader exists for the fallback, Cyclone matches it with a micros_rt publisher's writer
whatever was negotiated, and the camera crossed the link twice (13 images delivered instead of 34).

Keys are resolved topic names, :mod:`fnmatch` glob patterns (``*``, ``?``, ``[...]``; note that
``*`` also matches ``/``) or ``^...$`` regular expressions (:mod:`micros_rt.qos.topic_rules`, the
matcher every profile section uses). Lookup: an exact name beats any pattern; among matching patterns
the longest wins; equally long patterns: the first in the file wins. Values are the options'
``to_dict`` forms (durations in seconds, ``inf``/``.inf`` for forever, priority names or 0..6).
Deadline callbacks cannot be given in YAML; pass ``deadline_cb`` in code.

Code and file together (:func:`merge_advertise`, :func:`merge_subscribe`): **per field, a value given
in code that differs from the default wins; otherwise the file's value applies.** So a profile can
tune any option the code left at its default, and cannot override what the code chose explicitly.
(A code value explicitly set *to* the default cannot be told apart from "not given" and yields to the
file.)
"""

from __future__ import annotations

import dataclasses
import os
import re
from dataclasses import dataclass
from typing import Any, Mapping, TypeVar, Union

import yaml

from micros_rt.exceptions import MicrosRtError, ProfileError, UnsupportedQoSError
from micros_rt.negotiation.protocol import DDS, SHM, TCPROS
from micros_rt.qos.links import LinkSpec, LinkSpecError, parse_link
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.qos.topic_rules import TopicPattern, best_match

__all__ = ["QoSProfile", "merge_advertise", "merge_subscribe"]

_SECTIONS: dict[str, type[AdvertiseQoSOptions] | type[SubscribeQoSOptions]] = {
    "publishers": AdvertiseQoSOptions,
    "subscribers": SubscribeQoSOptions,
}


_Options = TypeVar("_Options", AdvertiseQoSOptions, SubscribeQoSOptions)


@dataclass(frozen=True)
class _Entry:
    key: str
    options: Union[AdvertiseQoSOptions, SubscribeQoSOptions]
    order: int


class QoSProfile:
    """Per-topic publisher and subscriber QoS options read from YAML.

    >>> profile = QoSProfile.from_string("publishers: {/chatter: {transport_priority: HIGH}}")
    >>> profile.advertise_options("/chatter").transport_priority
    <TransportPriority.HIGH: 4>
    """

    def __init__(
        self,
        publishers: Mapping[str, AdvertiseQoSOptions] | None = None,
        subscribers: Mapping[str, SubscribeQoSOptions] | None = None,
        *,
        source: str = "<code>",
    ) -> None:
        """Build a profile from ready option values (keys: topic names or glob patterns)."""
        self.source = source
        self._publishers: dict[str, AdvertiseQoSOptions] = dict(publishers or {})
        self._subscribers: dict[str, SubscribeQoSOptions] = dict(subscribers or {})
        # transport_hints by section: key -> protocol names (a subscriber's in the order offered)
        self._transports: dict[str, dict[str, tuple[str, ...]]] = {section: {} for section in _SECTIONS}
        # the raw ``mqtt`` section (broker and per-topic MQTT rules), validated by micros_rt.transports.mqtt.backend
        self.mqtt: Any = None
        #: the ``links`` section: links of limited bandwidth, in file order
        self.links: tuple[LinkSpec, ...] = ()
        #: the ``ros2`` switch: False keeps the node invisible to ROS 2 (DDS only where a peer needs it);
        #: None: not given (visible, unless MICROS_RT_ROS2 says otherwise)
        self.ros2: bool | None = None

    def __repr__(self) -> str:
        return (
            f"QoSProfile(source={self.source!r}, publishers={sorted(self._publishers)!r}, "
            f"subscribers={sorted(self._subscribers)!r})"
        )

    @property
    def publishers(self) -> dict[str, AdvertiseQoSOptions]:
        """A copy of the ``publishers`` section: key (name or pattern) -> options."""
        return dict(self._publishers)

    @property
    def subscribers(self) -> dict[str, SubscribeQoSOptions]:
        """A copy of the ``subscribers`` section: key (name or pattern) -> options."""
        return dict(self._subscribers)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> QoSProfile:
        """Read a profile file; errors are :class:`ProfileError` naming the file, line and key."""
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except OSError as exc:
            raise ProfileError(f"{os.fspath(path)}: cannot read QoS profile: {exc}") from exc
        return cls.from_string(text, source=os.fspath(path))

    @classmethod
    def from_string(cls, text: str, *, source: str = "<string>") -> QoSProfile:
        """Parse profile YAML ``text``; ``source`` names it in error messages."""
        try:
            # compose() keeps nodes with their line numbers; values are constructed per node below.
            root = yaml.compose(text, Loader=yaml.SafeLoader)
        except yaml.YAMLError as exc:
            raise ProfileError(f"{source}: not valid YAML: {exc}") from exc
        publishers: dict[str, AdvertiseQoSOptions] = {}
        subscribers: dict[str, SubscribeQoSOptions] = {}
        transports: dict[str, dict[str, tuple[str, ...]]] = {section: {} for section in _SECTIONS}
        if root is None:  # empty file: an empty profile
            return cls(publishers, subscribers, source=source)
        _expect_mapping(root, source, "the top level", "a mapping with 'publishers'/'subscribers'")
        mqtt: Any = None
        links: tuple[LinkSpec, ...] = ()
        ros2: bool | None = None
        for section_node, body in _pairs(root, source, ""):
            section = section_node.value
            if section == "ros2":
                value = _construct(body)
                if not isinstance(value, bool):
                    raise ProfileError(f"{_where(source, body)}: ros2: expected true (micros_rt topics are ROS 2 "
                                       f"topics too, the default) or false (no DDS until a peer on another host "
                                       f"needs it), got {value!r}")
                ros2 = value
                continue
            if section == "mqtt":
                mqtt = _construct(body)
                continue
            if section == "links":
                links = _parse_links(body, source)
                continue
            if section not in _SECTIONS:
                raise ProfileError(
                    f"{_where(source, section_node)}: unknown section {section!r}; "
                    f"expected {', '.join(repr(s) for s in (*_SECTIONS, 'links', 'mqtt', 'ros2'))}"
                )
            if _is_null(body):
                continue
            _expect_mapping(body, source, section, "a mapping of topic names/patterns to options")
            for topic_node, options_node in _pairs(body, source, section):
                topic = topic_node.value
                path = f"{section}[{topic!r}]"
                if not topic:
                    raise ProfileError(f"{_where(source, topic_node)}: {section}: empty topic key")
                try:
                    TopicPattern.parse(topic)
                except re.error as exc:
                    raise ProfileError(f"{_where(source, topic_node)}: {section}: key {topic!r} is not a valid "
                                       f"regular expression: {exc}") from None
                hints = _take_transport_hints(options_node, source, path, publisher=section == "publishers")
                if hints is not None:
                    transports[section][topic] = hints
                if section == "publishers":
                    publishers[topic] = _parse_options(
                        AdvertiseQoSOptions, options_node, source, path
                    )
                else:
                    subscribers[topic] = _parse_options(
                        SubscribeQoSOptions, options_node, source, path
                    )
        profile = cls(publishers, subscribers, source=source)
        profile._transports = transports
        profile.mqtt = mqtt
        profile.links = links
        profile.ros2 = ros2
        return profile

    def advertise_options(self, topic: str) -> AdvertiseQoSOptions | None:
        """Options the profile gives for publishing on the resolved ``topic``, or None."""
        return _lookup(self._publishers, topic)

    def subscribe_options(self, topic: str) -> SubscribeQoSOptions | None:
        """Options the profile gives for subscribing to the resolved ``topic``, or None."""
        return _lookup(self._subscribers, topic)


    def subscribe_transports(self, topic: str) -> tuple[str, ...] | None:
        """The transports (``"DDS"``, ``"TCPROS"``) in the order the profile has a subscriber of the resolved
        ``topic`` offer them, or None (the code's TransportHints or the default order)."""
        return _lookup(self._transports["subscribers"], topic)

    def advertise_transports(self, topic: str) -> tuple[str, ...] | None:
        """The transports the profile has a publisher of the resolved ``topic`` serve (``("TCPROS",)``: no
        DDS writer), or None (every transport this process has)."""
        return _lookup(self._transports["publishers"], topic)


_Value = TypeVar("_Value")


def _lookup(section: Mapping[str, _Value], topic: str) -> _Value | None:
    exact = section.get(topic)
    if exact is not None:
        return exact
    return best_match(((TopicPattern.parse(key), options) for key, options in section.items()), topic)


def _where(source: str, node: yaml.Node) -> str:
    return f"{source}:{node.start_mark.line + 1}"


def _is_null(node: yaml.Node) -> bool:
    return isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"


def _expect_mapping(node: yaml.Node, source: str, what: str, expected: str) -> None:
    if not isinstance(node, yaml.MappingNode):
        raise ProfileError(f"{_where(source, node)}: {what}: expected {expected}, got {_kind(node)}")


def _kind(node: yaml.Node) -> str:
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    if isinstance(node, yaml.ScalarNode):
        return f"the value {node.value!r}"
    return "a mapping"


def _pairs(node: yaml.Node, source: str, path: str) -> list[tuple[yaml.ScalarNode, yaml.Node]]:
    """Key/value node pairs of a mapping, with string keys and no duplicates (YAML allows both)."""
    assert isinstance(node, yaml.MappingNode)  # callers check with _expect_mapping first
    seen: dict[str, yaml.Node] = {}
    pairs: list[tuple[yaml.ScalarNode, yaml.Node]] = []
    for key_node, value_node in node.value:
        where = _where(source, key_node)
        if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
            shown = key_node.value if isinstance(key_node, yaml.ScalarNode) else _kind(key_node)
            raise ProfileError(f"{where}: {path or 'top level'}: key {shown!r} must be a string")
        if key_node.value in seen:
            first = seen[key_node.value].start_mark.line + 1
            raise ProfileError(
                f"{where}: {_child(path, key_node.value)}: duplicate key (first given on line {first})"
            )
        seen[key_node.value] = key_node
        pairs.append((key_node, value_node))
    return pairs


def _child(path: str, key: str) -> str:
    # The same spelling as the error messages elsewhere: publishers['/a'].latency_budget
    if not path:
        return key
    if path in _SECTIONS:
        return f"{path}[{key!r}]"
    return f"{path}.{key}"


def _construct(node: yaml.Node) -> Any:
    # A fresh SafeLoader's constructor turns one scalar node into its Python value (true -> True,
    # 0.5 -> 0.5, .inf -> inf) exactly as yaml.safe_load would.
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_object(node, deep=True)
    finally:
        loader.dispose()


def _parse_links(node: yaml.Node, source: str) -> tuple[LinkSpec, ...]:
    if _is_null(node):
        return ()
    _expect_mapping(node, source, "links", "a mapping of link names to {bandwidth, peers or interface}")
    found: list[LinkSpec] = []
    for name_node, body in _pairs(node, source, "links"):
        try:
            found.append(parse_link(name_node.value, _construct(body)))
        except LinkSpecError as exc:
            where = f"links.{name_node.value}.{exc.key}" if exc.key else f"links.{name_node.value}"
            raise ProfileError(f"{_where(source, body)}: {where}: {exc.text}") from None
    return tuple(found)


def _take_transport_hints(node: yaml.Node, source: str, path: str, *, publisher: bool) -> tuple[str, ...] | None:
    """Remove a ``transport_hints`` entry from an options mapping and return its protocols (a publisher's
    must include TCPROS)."""
    if not isinstance(node, yaml.MappingNode):
        return None  # _parse_options says what is wrong with it
    for i, (key_node, value_node) in enumerate(node.value):
        if isinstance(key_node, yaml.ScalarNode) and key_node.value == "transport_hints":
            break
    else:
        return None
    del node.value[i]
    where, key = _where(source, value_node), f"{path}.transport_hints"
    allowed = f"a list of {SHM!r}, {DDS!r} and {TCPROS!r} in the order preferred, e.g. [{TCPROS}, {DDS}]"
    if not isinstance(value_node, yaml.SequenceNode) or not value_node.value:
        raise ProfileError(f"{where}: {key}: expected {allowed}, got {_kind(value_node)}")
    names: list[str] = []
    for item in value_node.value:
        name = str(item.value).upper() if isinstance(item, yaml.ScalarNode) else ""
        if name not in (SHM, DDS, TCPROS):
            shown = item.value if isinstance(item, yaml.ScalarNode) else _kind(item)
            raise ProfileError(f"{_where(source, item)}: {key}: {shown!r} is not a transport; expected {allowed}")
        if name in names:
            raise ProfileError(f"{_where(source, item)}: {key}: {name} is given twice")
        names.append(name)
    if publisher and TCPROS not in names:
        raise ProfileError(f"{where}: {key}: a publisher always serves {TCPROS} (stock ROS subscribers connect "
                           f"with nothing else); [{TCPROS}] keeps the topic off {DDS}, [{DDS}, {TCPROS}] is the "
                           f"default")
    return tuple(names)


def _parse_options(
    cls: type[_Options], node: yaml.Node, source: str, path: str
) -> _Options:
    if _is_null(node):
        return cls()
    _expect_mapping(node, source, path, "a mapping of option names to values")
    values: dict[str, Any] = {}
    known = cls._KEYS
    for key_node, value_node in _pairs(node, source, path):
        key = key_node.value
        where = _where(source, key_node)
        if key == "deadline_cb":
            raise ProfileError(
                f"{where}: {path}.deadline_cb: deadline callbacks cannot be given in a YAML profile; "
                f"pass deadline_cb=... in code (the profile may still set deadline)"
            )
        if key not in known:
            raise ProfileError(
                f"{where}: {path}.{key}: unknown option; known options: {', '.join(known)}"
            )
        if not isinstance(value_node, yaml.ScalarNode):
            raise ProfileError(
                f"{_where(source, value_node)}: {path}.{key}: expected a single value, "
                f"got {_kind(value_node)}"
            )
        value = _construct(value_node)
        try:
            # Validate each option on its own so that the error points at its line.
            cls.from_dict({key: value}, source=source)
        except UnsupportedQoSError as exc:
            raise ProfileError(f"{_where(source, value_node)}: {path}.{key}: {exc}") from exc
        except MicrosRtError as exc:
            raise ProfileError(
                f"{_where(source, value_node)}: {path}.{key}: {value!r} is invalid: "
                f"{_expected_part(exc)}"
            ) from exc
        values[key] = value
    try:
        return cls.from_dict(values, source=source)
    except MicrosRtError as exc:  # combinations of options (none expressible today, but be safe)
        raise ProfileError(f"{_where(source, node)}: {path}: {exc}") from exc


def _expected_part(exc: Exception) -> str:
    # options.py phrases errors as "<option>=<value> is invalid: <what is allowed>"; keep the last part.
    text = str(exc)
    marker = " is invalid: "
    return text.split(marker, 1)[1] if marker in text else text


def _merge(cls: type[_Options], code: _Options | None, profile: _Options | None) -> _Options:
    if code is None and profile is None:
        return cls()
    if code is None:
        assert profile is not None
        return profile
    if profile is None:
        return code
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        code_value = getattr(code, f.name)
        if code_value == f.default:
            changes[f.name] = getattr(profile, f.name)
    # deadline_cb follows the same rule (None is its default); YAML profiles never carry one.
    return dataclasses.replace(code, **changes)


def merge_advertise(
    code: AdvertiseQoSOptions | None, profile: AdvertiseQoSOptions | None
) -> AdvertiseQoSOptions:
    """Combine options from code and from a profile: per field, a non-default code value wins.

    Fields the code left at their default take the profile's value. Either side may be None;
    both None gives the defaults.
    """
    return _merge(AdvertiseQoSOptions, code, profile)


def merge_subscribe(
    code: SubscribeQoSOptions | None, profile: SubscribeQoSOptions | None
) -> SubscribeQoSOptions:
    """Combine options from code and from a profile: per field, a non-default code value wins.

    Fields the code left at their default take the profile's value; ``deadline_cb`` always comes
    from code. Either side may be None; both None gives the defaults.
    """
    return _merge(SubscribeQoSOptions, code, profile)
