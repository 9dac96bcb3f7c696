"""The back-end interface: what a publication and a subscription ask of a data plane.

A back end (DDS today; MQTT and the microcontroller link next) opens one writer per publication and
one reader per subscription. The per-topic endpoints (:mod:`micros_rt._publication`,
:mod:`micros_rt._subscription`) talk to these few methods only, the way rospy's ``ProtocolHandler``
or httpx's transport interface keep their callers free of per-transport ``if`` chains. TCPROS stays
rospy's own (reached through :mod:`micros_rt._rospy_compat`): stock nodes must see stock rospy.

Publishing is two-phase so that a bad message is refused before anything is sent on any transport:
every writer ``prepare()``s (serializes, raising ``genpy.SerializationError``), then every writer
``send()``s what it prepared.
"""

from __future__ import annotations

from dataclasses import dataclass
import importlib
from typing import Any, Callable, Dict, List, Optional, Protocol, Sequence, Set, Tuple, Type

import genpy

from .qos import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = ["Backend", "EndpointSpec", "Feed", "MirrorWriter", "PROFILE_BACKENDS", "ProfileBackend", "ReaderBackend", "WriterBackend",
           "RemoteWriter", "Sample", "profile_backends"]


@dataclass(frozen=True)
class EndpointSpec:
    """One topic endpoint as the back end needs to know it."""

    topic: str                         # resolved ROS name
    data_class: Type[genpy.Message]
    queue_size: Optional[int]          # None/0: lossless (reliable, keep all, back-pressure)
    latch: bool                        # writer: keep the last message for late joiners; reader: want it
    tag: Dict[str, str]                # micros_rt identity (graph, node), visible to peers


@dataclass(frozen=True)
class RemoteWriter:
    """A peer writer a reader heard: its id and its micros_rt tag (None for foreign, e.g. ROS 2)."""

    guid: str
    tag: Optional[Dict[str, str]]


#: One received sample: (serialized payload, info) where ``info`` has ``valid_data`` (bool),
#: ``source_timestamp`` (ns) and ``publication_handle`` (the writer, for :meth:`ReaderBackend.writer`).
#: Cyclone's own SampleInfo has exactly these, so the DDS path builds no object per sample.
Sample = Tuple[bytes, Any]


class WriterBackend(Protocol):
    protocol: str
    guid: str

    def prepare(self, msg: Any) -> Any:
        """Serialize ``msg`` for this transport; raise ``genpy.SerializationError`` on a bad value."""

    def send(self, prepared: Any) -> None:
        """Send what :meth:`prepare` returned; may block on back-pressure (bounded, then raises)."""

    def matched_peers(self) -> Set[str]:
        """Ids of the readers this writer reaches now."""

    def close(self) -> None: ...


class ReaderBackend(Protocol):
    protocol: str
    guid: str

    def take(self, n: int) -> Sequence[Sample]:
        """Up to ``n`` received samples, oldest first, without blocking."""

    def decode(self, payload: bytes) -> Any:
        """A genpy message from a payload; raise ``ValueError`` on a malformed one."""

    def writer(self, handle: Any) -> Optional[RemoteWriter]:
        """The writer behind a sample's handle (None when it is already gone)."""

    def matched_writers(self) -> Set[str]:
        """Ids of the writers this reader hears now."""

    def close(self) -> None: ...


class Backend(Protocol):
    """A data plane: opens writers and readers. ``wake`` is called (from any thread) when data or a
    match arrives; a back end may instead expose a native wait condition the inbox attaches to."""

    protocol: str

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> WriterBackend: ...

    def open_reader(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                    wake: Callable[[], None], on_incompatible: Callable[[int], None]) -> ReaderBackend: ...

    def describe(self) -> List[str]:
        """Words for ``rosnode info`` and logs (domain, interface)."""


# ---------------------------------------------------------------------------------------------------
# Back ends a YAML profile attaches to topics beside the negotiated DDS/TCPROS link (MQTT today).
# A publication mirrors its messages to each writer they open; a subscription is fed by each feed,
# through the same delivery path as its TCPROS links (time filter, deadline, statistics).


class MirrorWriter(Protocol):
    """A profile back end's writer: two-phase like :class:`WriterBackend` (prepare raises on a bad value
    before anything is sent anywhere; send does not raise for a peer or broker that is away)."""

    protocol: str

    def prepare(self, msg: Any) -> Any: ...

    def send(self, prepared: Any) -> None: ...

    def close(self) -> None: ...


class Feed(Protocol):
    """Messages from a profile back end into a subscription (``deliver(msg)`` per message)."""

    protocol: str

    def transports(self) -> Dict[str, str]:
        """Link id -> protocol name, for ``Subscriber.connection_transports()``."""

    def close(self) -> None: ...


class ProfileBackend(Protocol):
    """A back end chosen per topic by the YAML profile: opens a writer or a feed when one of its rules
    names the topic, else returns None."""

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> Optional[MirrorWriter]: ...

    def open_feed(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                  deliver: Callable[[Any], None]) -> Optional[Feed]: ...


#: profile section -> module whose ``profile_backend(profile, graph=..., node=...)`` returns the
#: :class:`ProfileBackend` for it. Imported only when a node's profile has that section.
PROFILE_BACKENDS: Dict[str, str] = {"mqtt": "micros_rt.mqtt"}


def profile_backends(profile: Any, *, graph: str, node: str) -> Tuple[ProfileBackend, ...]:
    """The profile back ends ``profile`` (a :class:`micros_rt.QoSProfile` or None) asks for."""
    if profile is None:
        return ()
    found: List[ProfileBackend] = []
    for section, module in PROFILE_BACKENDS.items():
        if getattr(profile, section, None):
            found.append(importlib.import_module(module).profile_backend(profile, graph=graph, node=node))
    return tuple(found)
