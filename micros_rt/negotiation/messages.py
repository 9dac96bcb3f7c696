"""Typed DDS offer (subscriber -> publisher) and answer (publisher -> subscriber) of ``requestTopic``.

Both sides build and read these values only through :meth:`to_xmlrpc` / :meth:`from_xmlrpc`, so the
keys one side writes are the keys the other reads. ``from_xmlrpc`` validates everything a remote node
sends (types, lengths, GUID format) and raises :class:`MalformedNegotiationError` naming the field;
nothing from the wire is trusted or kept unvalidated.

>>> offer = DDSOffer(domain=0, topic="rt/chatter", type_name="std_msgs::msg::dds_::String_",
...                  md5="992ce8a1687cec8c8bd883ec73ca41d1", qos=SubscribeQoSOptions(),
...                  reader="01106fda-d45a-29f3-b1ee-b181000001c1",
...                  participant="01106fda-d45a-29f3-b1ee-b181000001c1", graph="run@uri")
>>> DDSOffer.from_xmlrpc(offer.to_xmlrpc()[1]) == offer
True
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Type, TypeVar

from ..exceptions import MicrosRtError, QoSTypeError, QoSValueError
from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions
from .protocol import DDS, MAX_FIELD_CHARS, SHM

__all__ = ["DDSOffer", "DDSAnswer", "DDSOpenFirst", "MalformedNegotiationError", "ShmAnswer", "ShmOffer", "is_guid"]

_GUID = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")
_INT32 = (-(2 ** 31), 2 ** 31 - 1)


class MalformedNegotiationError(MicrosRtError, ValueError):
    """A DDS offer or answer from another node is not what micros_rt sends; ``field`` names the key."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


def is_guid(value: object) -> bool:
    """True for Cyclone's textual GUID form (``01106fda-d45a-29f3-b1ee-b181000001c1``)."""
    return isinstance(value, str) and bool(_GUID.fullmatch(value))


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _mapping(params: object, what: str) -> Mapping[str, Any]:
    if not isinstance(params, dict):
        raise MalformedNegotiationError(what, f"expected a struct, got {type(params).__name__}")
    return params


def _str(d: Mapping[str, Any], key: str, *, required: bool = True, guid: bool = False) -> str:
    value = d.get(key)
    if value is None and not required:
        return ""
    if not isinstance(value, str):
        raise MalformedNegotiationError(key, f"expected a string, got {_short(value)}")
    if len(value) > MAX_FIELD_CHARS:
        raise MalformedNegotiationError(key, f"{len(value)} characters, at most {MAX_FIELD_CHARS} allowed")
    if guid and not is_guid(value):
        raise MalformedNegotiationError(key, f"{_short(value)} is not a DDS GUID")
    return value


#: a resolved (global) ROS name as rosgraph.names.is_legal_name accepts them, without a trailing slash
_ROS_NAME = re.compile(r"^(/[A-Za-z0-9_]+)+$")


def _topic_name(d: Mapping[str, Any], key: str) -> str:
    """An optional resolved ROS topic name (``/robot_a/chatter``): what a subscriber may open a reader on."""
    value = _str(d, key, required=False)
    if value and not _ROS_NAME.fullmatch(value):
        raise MalformedNegotiationError(key, f"{_short(value)} is not a resolved ROS topic name")
    return value


def _bool(d: Mapping[str, Any], key: str) -> bool:
    value = d.get(key, False)
    if not isinstance(value, bool):
        raise MalformedNegotiationError(key, f"expected a boolean, got {_short(value)}")
    return value


Q = TypeVar("Q", SubscribeQoSOptions, AdvertiseQoSOptions)


def _qos(cls: Type[Q], d: Mapping[str, Any], source: str) -> Q:
    """The ``qos`` struct of an offer or answer as ``cls`` (MalformedNegotiationError naming the field)."""
    try:
        return cls.from_dict(_qos_dict(d), source=source)
    except (QoSValueError, QoSTypeError) as exc:
        raise MalformedNegotiationError("qos", str(exc)[:300]) from exc


def _qos_dict(d: Mapping[str, Any]) -> Mapping[str, Any]:
    qos = d.get("qos", {})
    if not isinstance(qos, dict) or len(qos) > 16:
        raise MalformedNegotiationError("qos", f"expected a struct of QoS options, got {_short(qos)}")
    for key, value in qos.items():
        if (isinstance(key, str) and len(key) > MAX_FIELD_CHARS) or (isinstance(value, str)
                                                                     and len(value) > MAX_FIELD_CHARS):
            raise MalformedNegotiationError("qos", f"option {_short(key)}: at most {MAX_FIELD_CHARS} characters")
    return qos


@dataclass(frozen=True)
class DDSOffer:
    """What a micros_rt subscriber offers in its ``['DDS', {...}]`` protocol entry."""

    domain: int
    topic: str
    type_name: str
    md5: str
    qos: SubscribeQoSOptions
    reader: str
    participant: str
    graph: str
    #: The subscriber wants the latched message (a transient-local reader).
    transient_local: bool = False
    #: The subscriber opens a reader on another DDS topic when an answer names one (``DDSAnswer.topic``).
    follow: bool = False
    #: The subscriber has no DDS reader yet (it makes DDS entities only when a peer needs them): a publisher
    #: that would take DDS answers :class:`DDSOpenFirst`, and the subscriber opens its reader and asks again.
    #: ``topic``, ``type_name``, ``reader`` and ``participant`` are empty then.
    lazy: bool = False

    def to_xmlrpc(self) -> List[Any]:
        """The protocol entry, ``['DDS', {...}]`` (roscpp needs every entry to be a list)."""
        if self.lazy:
            return [DDS, {"lazy": True, "domain": self.domain, "md5": self.md5, "qos": self.qos.to_dict(),
                          "graph": self.graph}]
        return [DDS, {
            "domain": self.domain, "topic": self.topic, "type": self.type_name, "md5": self.md5,
            "qos": self.qos.to_dict(), "reader": self.reader, "participant": self.participant,
            "graph": self.graph, "transient_local": self.transient_local, "follow": self.follow,
        }]

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a subscriber") -> "DDSOffer":
        d = _mapping(params, "DDS offer")
        domain = d.get("domain")
        if isinstance(domain, bool) or not isinstance(domain, int) or not _INT32[0] <= domain <= _INT32[1]:
            raise MalformedNegotiationError("domain", f"expected an integer DDS domain id, got {_short(domain)}")
        qos = _qos(SubscribeQoSOptions, d, source)
        if _bool(d, "lazy"):
            return cls(domain=domain, topic="", type_name="", md5=_str(d, "md5"), qos=qos, reader="",
                       participant="", graph=_str(d, "graph"), lazy=True)
        return cls(domain=domain, topic=_str(d, "topic"), type_name=_str(d, "type"), md5=_str(d, "md5"),
                   qos=qos, reader=_str(d, "reader", guid=True),
                   participant=_str(d, "participant", guid=True), graph=_str(d, "graph"),
                   transient_local=_bool(d, "transient_local"), follow=_bool(d, "follow"))


@dataclass(frozen=True)
class DDSOpenFirst:
    """A publisher's answer to a lazy DDS offer (:attr:`DDSOffer.lazy`): it would take DDS; the subscriber opens
    its DDS reader and asks again with a full offer. ``['DDS', {'open_first': True}]``."""

    def to_xmlrpc(self) -> List[Any]:
        return [DDS, {"open_first": True}]

    @staticmethod
    def is_one(entry: object) -> bool:
        return (isinstance(entry, list) and len(entry) == 2 and entry[0] == DDS and isinstance(entry[1], dict)
                and entry[1].get("open_first") is True)


@dataclass(frozen=True)
class DDSAnswer:
    """What a micros_rt publisher answers when it accepts DDS: ``['DDS', {...}]``."""

    writer: str
    participant: str
    latch: bool
    qos: AdvertiseQoSOptions
    node: str = ""
    #: Not empty: the publisher republishes another graph's topic that reaches this domain already, and
    #: serves its DDS subscribers with the writers of that graph's relay (tag ``relay=<via>``), not its own
    #: (``writer`` is one of them): no second hop through the publisher's process.
    via: str = ""
    #: With ``via``: the ROS name of the topic those writers write when it is not the subscriber's own (an
    #: import renamed by the relay); the subscriber reads it with a reader of its own (``DDSOffer.follow``).
    topic: str = ""

    def to_xmlrpc(self) -> List[Any]:
        return [DDS, self.params()]

    def params(self) -> Dict[str, Any]:
        params = {"writer": self.writer, "participant": self.participant, "latch": self.latch,
                  "qos": self.qos.to_dict(), "node": self.node}
        if self.via:
            params["via"] = self.via
        if self.topic:
            params["topic"] = self.topic
        return params

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a publisher") -> "DDSAnswer":
        d = _mapping(params, "DDS answer")
        qos = _qos(AdvertiseQoSOptions, d, source)
        return cls(writer=_str(d, "writer", guid=True), participant=_str(d, "participant", guid=True),
                   latch=_bool(d, "latch"), qos=qos, node=_str(d, "node", required=False),
                   via=_str(d, "via", required=False), topic=_topic_name(d, "topic"))


#: A shared-memory channel's name as a publisher makes them (:mod:`micros_rt.transports.shm`).
_CHANNEL = re.compile(r"^micros_rt/[0-9a-f]{8,64}$")


@dataclass(frozen=True)
class ShmOffer:
    """What a micros_rt subscriber offers in its ``['SHM', {...}]`` protocol entry: where it runs (``host``:
    the machine's boot id, network and mount namespaces and Unix user, so two network-namespace "hosts" of
    one machine never share memory) and what it reads."""

    host: str
    md5: str
    type_name: str        # the ROS type, e.g. std_msgs/String
    qos: SubscribeQoSOptions
    #: the subscriber wants the latched message
    transient_local: bool = False
    #: the subscriber's process id (same host): the publisher notices a SIGKILLed subscriber by it
    pid: int = 0
    #: the channel this subscriber already reads from this publisher ("" none): asked again on a publisher
    #: update, the publisher keeps it (a new channel would lose what the old one still holds)
    held: str = ""

    def to_xmlrpc(self) -> List[Any]:
        params = {"host": self.host, "md5": self.md5, "type": self.type_name, "qos": self.qos.to_dict(),
                  "transient_local": self.transient_local, "pid": self.pid}
        if self.held:
            params["held"] = self.held
        return [SHM, params]

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a subscriber") -> "ShmOffer":
        d = _mapping(params, "SHM offer")
        qos = _qos(SubscribeQoSOptions, d, source)
        return cls(host=_str(d, "host"), md5=_str(d, "md5"), type_name=_str(d, "type"), qos=qos,
                   transient_local=_bool(d, "transient_local"), pid=_pid(d), held=_str(d, "held", required=False))


def _pid(d: Mapping[str, Any]) -> int:
    value = d.get("pid", 0)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _INT32[1]:
        raise MalformedNegotiationError("pid", f"expected a process id, got {_short(value)}")
    return value


@dataclass(frozen=True)
class ShmAnswer:
    """What a micros_rt publisher answers when it accepts SHM: ``['SHM', {...}]``, the channel it made for
    this subscriber (its own shared-memory service: no other subscriber reads it, so nothing arrives twice)."""

    channel: str
    latch: bool
    qos: AdvertiseQoSOptions
    node: str = ""
    #: the publisher's process id (same host): the subscriber notices a SIGKILLed publisher by it
    pid: int = 0

    def to_xmlrpc(self) -> List[Any]:
        return [SHM, {"channel": self.channel, "latch": self.latch, "qos": self.qos.to_dict(), "node": self.node,
                      "pid": self.pid}]

    @classmethod
    def from_xmlrpc(cls, params: object, *, source: str = "a publisher") -> "ShmAnswer":
        d = _mapping(params, "SHM answer")
        qos = _qos(AdvertiseQoSOptions, d, source)
        channel = _str(d, "channel")
        if not _CHANNEL.fullmatch(channel):
            raise MalformedNegotiationError("channel", f"{_short(channel)} is not a micros_rt shared-memory channel")
        return cls(channel=channel, latch=_bool(d, "latch"), qos=qos, node=_str(d, "node", required=False),
                   pid=_pid(d))
