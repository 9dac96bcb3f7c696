"""Reading a YAML configuration with line numbers: what QoS profiles and the bridges' files share.

A file is composed into nodes (:func:`compose`), never loaded straight to Python values, so that every error
names the file and the line of the offending key or value (:func:`location`). Each function raises
:class:`~micros_rt.exceptions.ProfileError` with one line of words, ``<file>:<line>: <key path>: <what is
wrong>``; a program with an error type of its own re-raises it with the same text.

A program reads its whole file with :func:`load_document` (or its text with :func:`parse_document`): the file
read, an empty document refused, its own parser given the root node, and every error of the shared helpers
raised as the program's error type with the same text.

>>> root = compose("relay: {queue_size: 5}\\n", source="relay.yaml")
>>> [(key.value, node_value(body)) for key, body in mapping_items(root, "relay.yaml", "")]
[('relay', {'queue_size': 5})]
>>> options = parse_qos_options(SubscribeQoSOptions, compose("{deadline: 0.5}", source="f"), "f", "import")
>>> options.deadline
0.5
>>> parse_qos_options(SubscribeQoSOptions, compose("{deadline: -1}", source="f.yaml"), "f.yaml", "import")
Traceback (most recent call last):
...
micros_rt.exceptions.ProfileError: f.yaml:1: import.deadline: -1 is invalid: ...
"""

from __future__ import annotations

import os
from typing import Any, Callable, Sequence, TypeVar

import yaml

from micros_rt.exceptions import MicrosRtError, ProfileError, UnsupportedQoSError
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = ["compose", "describe_node", "expect_mapping", "is_null", "load_document", "location", "mapping_items",
           "node_value", "parse_document", "parse_qos_options", "sub_mapping"]

_Options = TypeVar("_Options", AdvertiseQoSOptions, SubscribeQoSOptions)
_Parsed = TypeVar("_Parsed")


def load_document(path: str | os.PathLike[str], parse: Callable[[yaml.Node, str], _Parsed], *, what: str,
                  empty: str, error: type[MicrosRtError] = ProfileError) -> _Parsed:
    """Read the YAML file at ``path`` and :func:`parse_document` it (its path names it in errors); a file that
    cannot be read raises ``error``: ``<file>: cannot read <what>: <reason>``."""
    source = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as exc:
        raise error(f"{source}: cannot read {what}: {exc}") from exc
    return parse_document(text, parse, source=source, empty=empty, error=error)


def parse_document(text: str, parse: Callable[[yaml.Node, str], _Parsed], *, source: str, empty: str,
                   error: type[MicrosRtError] = ProfileError) -> _Parsed:
    """``parse(root, source)`` of YAML ``text``'s root node. An empty document raises ``error``:
    ``<source>: <empty>``; any other micros_rt error (invalid YAML, the shared helpers' ProfileError) is
    raised as ``error`` with the same text."""
    try:
        root = compose(text, source=source)
        if root is None:
            raise error(f"{source}: {empty}")
        return parse(root, source)
    except MicrosRtError as exc:
        if isinstance(exc, error):
            raise
        raise error(str(exc)) from exc


def compose(text: str, *, source: str) -> yaml.Node | None:
    """The root node of YAML ``text`` (None for an empty document); ``source`` names it in errors."""
    try:
        # compose() keeps nodes with their line numbers; values are constructed per node (node_value)
        return yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise ProfileError(f"{source}: not valid YAML: {exc}") from exc


def location(source: str, node: yaml.Node) -> str:
    """``<source>:<line>`` of ``node``, the start of every error message."""
    return f"{source}:{node.start_mark.line + 1}"


def is_null(node: yaml.Node) -> bool:
    """Whether ``node`` is YAML's null (``~``, ``null`` or nothing after the key)."""
    return isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"


def describe_node(node: yaml.Node) -> str:
    """What ``node`` is, in words for an error: ``a list``, ``a mapping`` or ``the value 'x'``."""
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    if isinstance(node, yaml.ScalarNode):
        return f"the value {node.value!r}"
    return "a mapping"


def expect_mapping(node: yaml.Node, source: str, what: str, expected: str) -> None:
    """Raise unless ``node`` is a mapping: ``<file>:<line>: <what>: expected <expected>, got <what it is>``."""
    if not isinstance(node, yaml.MappingNode):
        raise ProfileError(f"{location(source, node)}: {what}: expected {expected}, got {describe_node(node)}")


def mapping_items(node: yaml.Node, source: str, path: str, *,
                  keys_are_names: bool = False) -> list[tuple[yaml.ScalarNode, yaml.Node]]:
    """Key/value node pairs of a mapping (check it with :func:`expect_mapping` first), refusing keys that are
    not strings and keys given twice (YAML allows both). ``path`` names the mapping in errors (``""``: the top
    level); its keys are spelt ``path.key``, or ``path['key']`` with ``keys_are_names`` (topic names)."""
    assert isinstance(node, yaml.MappingNode)  # callers check with expect_mapping first
    seen: dict[str, yaml.Node] = {}
    pairs: list[tuple[yaml.ScalarNode, yaml.Node]] = []
    for key_node, value_node in node.value:
        where = location(source, key_node)
        if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
            shown = key_node.value if isinstance(key_node, yaml.ScalarNode) else describe_node(key_node)
            raise ProfileError(f"{where}: {path or 'top level'}: key {shown!r} must be a string")
        if key_node.value in seen:
            first = seen[key_node.value].start_mark.line + 1
            child = key_node.value if not path else (f"{path}[{key_node.value!r}]" if keys_are_names
                                                     else f"{path}.{key_node.value}")
            raise ProfileError(f"{where}: {child}: duplicate key (first given on line {first})")
        seen[key_node.value] = key_node
        pairs.append((key_node, value_node))
    return pairs


def sub_mapping(like: yaml.Node, pairs: Sequence[tuple[yaml.Node, yaml.Node]]) -> yaml.MappingNode:
    """A mapping node of some of ``like``'s pairs (at ``like``'s lines): a program takes its own keys out of
    an options mapping and has :func:`parse_qos_options` validate the rest."""
    return yaml.MappingNode("tag:yaml.org,2002:map", list(pairs), like.start_mark, like.end_mark)


def node_value(node: yaml.Node) -> Any:
    """The Python value of ``node`` and everything below it, exactly as :func:`yaml.safe_load` gives it
    (``true`` -> True, ``0.5`` -> 0.5, ``.inf`` -> inf)."""
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_object(node, deep=True)
    finally:
        loader.dispose()


def parse_qos_options(cls: type[_Options], node: yaml.Node, source: str, path: str) -> _Options:
    """QoS options of ``cls`` (:class:`~micros_rt.AdvertiseQoSOptions` or :class:`~micros_rt.SubscribeQoSOptions`)
    from a mapping of option names to values (null: the defaults), each validated on its own so that an error
    names its line: ``<file>:<line>: <path>.<option>: <value> is invalid: <what is allowed>``."""
    if is_null(node):
        return cls()
    expect_mapping(node, source, path, "a mapping of option names to values")
    values: dict[str, Any] = {}
    known = cls._KEYS
    for key_node, value_node in mapping_items(node, source, path):
        key = key_node.value
        where = location(source, key_node)
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
                f"{location(source, value_node)}: {path}.{key}: expected a single value, "
                f"got {describe_node(value_node)}"
            )
        value = node_value(value_node)
        try:
            # Validate each option on its own so that the error points at its line.
            cls.from_dict({key: value}, source=source)
        except UnsupportedQoSError as exc:
            raise ProfileError(f"{location(source, value_node)}: {path}.{key}: {exc}") from exc
        except MicrosRtError as exc:
            raise ProfileError(
                f"{location(source, value_node)}: {path}.{key}: {value!r} is invalid: "
                f"{_expected_part(exc)}"
            ) from exc
        values[key] = value
    try:
        return cls.from_dict(values, source=source)
    except MicrosRtError as exc:  # combinations of options (none expressible today, but be safe)
        raise ProfileError(f"{location(source, node)}: {path}: {exc}") from exc


def _expected_part(exc: Exception) -> str:
    # options.py phrases errors as "<option>=<value> is invalid: <what is allowed>"; keep the last part.
    text = str(exc)
    marker = " is invalid: "
    return text.split(marker, 1)[1] if marker in text else text
