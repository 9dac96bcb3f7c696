"""Shared memory's offer (subscriber -> publisher) and answer (publisher -> subscriber) of ``requestTopic``, and
the publisher's decision on an offer (:func:`decide_shm`, a pure function with a verdict and a reason).

Both sides build and read these values only through ``to_xmlrpc`` / ``from_xmlrpc``; ``from_xmlrpc`` validates
everything a remote node sends and raises :class:`~micros_rt.negotiation.MalformedNegotiationError` naming the
field.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, List, Mapping, Optional

from ...negotiation import (INT32, SHM, MalformedNegotiationError, PublicationFacts, Verdict, qos_mismatch,
                            read_bool, read_qos, read_str, read_struct, short)
from ...qos import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = ["ShmAnswer", "ShmOffer", "decide_shm"]

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
        d = read_struct(params, "SHM offer")
        qos = read_qos(SubscribeQoSOptions, d, source)
        return cls(host=read_str(d, "host"), md5=read_str(d, "md5"), type_name=read_str(d, "type"), qos=qos,
                   transient_local=read_bool(d, "transient_local"), pid=_pid(d),
                   held=read_str(d, "held", required=False))


def _pid(d: Mapping[str, Any]) -> int:
    value = d.get("pid", 0)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= INT32[1]:
        raise MalformedNegotiationError("pid", f"expected a process id, got {short(value)}")
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
        d = read_struct(params, "SHM answer")
        qos = read_qos(AdvertiseQoSOptions, d, source)
        channel = read_str(d, "channel")
        if not _CHANNEL.fullmatch(channel):
            raise MalformedNegotiationError("channel", f"{short(channel)} is not a micros_rt shared-memory channel")
        return cls(channel=channel, latch=read_bool(d, "latch"), qos=qos,
                   node=read_str(d, "node", required=False), pid=_pid(d))


def decide_shm(offer: ShmOffer, facts: PublicationFacts, *, host: str, unavailable: Optional[str],
               subscriber: str) -> Verdict:
    """Accept ``offer`` for shared memory, or say why not. ``host`` is this publisher's host identity
    (:func:`micros_rt.transports.shm.host_identity`), ``unavailable`` why shared memory cannot be used in
    this process (None: it can).

    >>> facts = PublicationFacts("/chatter", "", None, "", "992c", AdvertiseQoSOptions(), latch=False)
    >>> offer = ShmOffer("boot/net/mnt/1000", "992c", "std_msgs/String", SubscribeQoSOptions())
    >>> decide_shm(offer, facts, host="boot/net/mnt/1000", unavailable=None, subscriber="/l").kind
    'accepted'
    >>> decide_shm(offer, facts, host="other/net/mnt/1000", unavailable=None, subscriber="/l").quiet
    True
    """
    topic = facts.topic
    if offer.host != host:
        # a subscriber on another machine or network namespace is the normal case: no warning
        same_machine = offer.host.split("/")[:3] == host.split("/")[:3]
        same_user = same_machine and offer.host.split("/")[3:4] == host.split("/")[3:4]
        why = ("keeps its shared memory elsewhere (another micros_rt version: its iceoryx2 directory is not this "
               "one's)" if same_user else
               "runs as another Unix user (processes of different users cannot share iceoryx2 memory)"
               if same_machine else "is on another host")
        return Verdict(False, "shm-host", f"topic {topic}: subscriber {subscriber} {why}; not using shared memory",
                       quiet=not same_machine)
    if unavailable is not None:
        return Verdict(False, "shm-unavailable", f"topic {topic}: subscriber {subscriber} asked for shared memory "
                                                 f"but this publisher cannot use it: {unavailable}")
    if offer.md5 not in ("*", facts.md5):
        return Verdict(False, "md5", f"topic {topic}: message type mismatch with {subscriber} (md5 {offer.md5} vs "
                                     f"{facts.md5}); not using shared memory")
    mismatch = qos_mismatch(offer.qos, offer.transient_local, facts,
                             f"QoS mismatch with subscriber {subscriber}, not using shared memory")
    if mismatch is not None:
        return mismatch
    return Verdict(True, "accepted", f"topic {topic}: shared memory accepted for subscriber {subscriber}")
