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

The file is read with :mod:`micros_rt.qos.yamlconfig` (errors name the file, the line and the key), which
the bridges' configuration files share.

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
from typing import Any, Iterable, Mapping, Sequence, TypeVar

import yaml

from micros_rt.exceptions import ProfileError
from micros_rt.negotiation.protocol import DDS, SHM, TCPROS
from micros_rt.qos.links import LinkSpec, LinkSpecError, parse_link
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.qos.topic_rules import TopicPattern, best_match
from micros_rt.qos.yamlconfig import (compose, describe_node, expect_mapping, is_null, location, mapping_items,
                                      node_value, parse_qos_options)

__all__ = ["QoSProfile", "merge_advertise", "merge_subscribe"]

_SECTIONS: dict[str, type[AdvertiseQoSOptions] | type[SubscribeQoSOptions]] = {
    "publishers": AdvertiseQoSOptions,
    "subscribers": SubscribeQoSOptions,
}


_Options = TypeVar("_Options", AdvertiseQoSOptions, SubscribeQoSOptions)


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
        root = compose(text, source=source)
        publishers: dict[str, AdvertiseQoSOptions] = {}
        subscribers: dict[str, SubscribeQoSOptions] = {}
        transports: dict[str, dict[str, tuple[str, ...]]] = {section: {} for section in _SECTIONS}
        if root is None:  # empty file: an empty profile
            return cls(publishers, subscribers, source=source)
        expect_mapping(root, source, "the top level", "a mapping with 'publishers'/'subscribers'")
        mqtt: Any = None
        links: tuple[LinkSpec, ...] = ()
        ros2: bool | None = None
        for section_node, body in mapping_items(root, source, ""):
            section = section_node.value
            if section == "ros2":
                value = node_value(body)
                if not isinstance(value, bool):
                    raise ProfileError(f"{location(source, body)}: ros2: expected true (micros_rt topics are ROS 2 "
                                       f"topics too, the default) or false (no DDS until a peer on another host "
                                       f"needs it), got {value!r}")
                ros2 = value
                continue
            if section == "mqtt":
                mqtt = node_value(body)
                continue
            if section == "links":
                links = _parse_links(body, source)
                continue
            if section not in _SECTIONS:
                raise ProfileError(
                    f"{location(source, section_node)}: unknown section {section!r}; "
                    f"expected {', '.join(repr(s) for s in (*_SECTIONS, 'links', 'mqtt', 'ros2'))}"
                )
            if is_null(body):
                continue
            expect_mapping(body, source, section, "a mapping of topic names/patterns to options")
            for topic_node, options_node in mapping_items(body, source, section, keys_are_names=True):
                topic = topic_node.value
                path = f"{section}[{topic!r}]"
                if not topic:
                    raise ProfileError(f"{location(source, topic_node)}: {section}: empty topic key")
                try:
                    TopicPattern.parse(topic)
                except re.error as exc:
                    raise ProfileError(f"{location(source, topic_node)}: {section}: key {topic!r} is not a valid "
                                       f"regular expression: {exc}") from None
                hints = _take_transport_hints(options_node, source, path, publisher=section == "publishers")
                if hints is not None:
                    transports[section][topic] = hints
                if section == "publishers":
                    publishers[topic] = parse_qos_options(
                        AdvertiseQoSOptions, options_node, source, path
                    )
                else:
                    subscribers[topic] = parse_qos_options(
                        SubscribeQoSOptions, options_node, source, path
                    )
        profile = cls(publishers, subscribers, source=source)
        profile._transports = transports
        profile.mqtt = mqtt
        profile.links = links
        profile.ros2 = ros2
        return profile

    def with_advertise_transports(self, topics: Iterable[str], transports: Sequence[str]) -> QoSProfile:
        """A copy of this profile whose publishers of ``topics`` (names or patterns) serve only ``transports``, as
        ``transport_hints`` in the file would say (``("TCPROS",)``: no DDS writer); their options stay.

        >>> QoSProfile().with_advertise_transports(["/scan"], ["TCPROS"]).advertise_transports("/scan")
        ('TCPROS',)
        """
        names = tuple(str(t).upper() for t in transports)
        if TCPROS not in names or any(n not in (SHM, DDS, TCPROS) for n in names):
            raise ProfileError(f"{self.source}: a publisher's transports must be {SHM!r}, {DDS!r} or {TCPROS!r}, "
                               f"{TCPROS!r} among them (stock subscribers connect with nothing else), got {names!r}")
        copy = QoSProfile(self._publishers, self._subscribers, source=self.source)
        copy._transports = {section: dict(hints) for section, hints in self._transports.items()}
        copy._transports["publishers"].update((topic, names) for topic in topics)
        copy.mqtt, copy.links, copy.ros2 = self.mqtt, self.links, self.ros2
        return copy

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


def _parse_links(node: yaml.Node, source: str) -> tuple[LinkSpec, ...]:
    if is_null(node):
        return ()
    expect_mapping(node, source, "links", "a mapping of link names to {bandwidth, peers or interface}")
    found: list[LinkSpec] = []
    for name_node, body in mapping_items(node, source, "links"):
        try:
            found.append(parse_link(name_node.value, node_value(body)))
        except LinkSpecError as exc:
            where = f"links.{name_node.value}.{exc.key}" if exc.key else f"links.{name_node.value}"
            raise ProfileError(f"{location(source, body)}: {where}: {exc.text}") from None
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
    where, key = location(source, value_node), f"{path}.transport_hints"
    allowed = f"a list of {SHM!r}, {DDS!r} and {TCPROS!r} in the order preferred, e.g. [{TCPROS}, {DDS}]"
    if not isinstance(value_node, yaml.SequenceNode) or not value_node.value:
        raise ProfileError(f"{where}: {key}: expected {allowed}, got {describe_node(value_node)}")
    names: list[str] = []
    for item in value_node.value:
        name = str(item.value).upper() if isinstance(item, yaml.ScalarNode) else ""
        if name not in (SHM, DDS, TCPROS):
            shown = item.value if isinstance(item, yaml.ScalarNode) else describe_node(item)
            raise ProfileError(f"{location(source, item)}: {key}: {shown!r} is not a transport; expected {allowed}")
        if name in names:
            raise ProfileError(f"{location(source, item)}: {key}: {name} is given twice")
        names.append(name)
    if publisher and TCPROS not in names:
        raise ProfileError(f"{where}: {key}: a publisher always serves {TCPROS} (stock ROS subscribers connect "
                           f"with nothing else); [{TCPROS}] keeps the topic off {DDS}, [{DDS}, {TCPROS}] is the "
                           f"default")
    return tuple(names)


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
