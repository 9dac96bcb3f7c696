"""The one reader of DDS discovery: what a participant has discovered on its domain, from Cyclone's built-in
DCPSParticipant, DCPSPublication and DCPSSubscription topics (read, never taken: every call sees all that is
alive now; the ``followed_*`` views take, each from its own reader or kind, and keep what came), and ROS 2's
``ros_discovery_info`` (which nodes each participant announces).

Its users: the relay's directories of writers and readers (:class:`~micros_rt.transports.dds.feed.WriterDirectory`,
the ``ros2:`` section), the host's ROS 2 watcher (:mod:`micros_rt.transports.dds.watch`) and the tools' view of the
ROS 2 graph (``micros-rt topic list``, ``node list``). None of them names a Cyclone class: what they get are
:class:`DiscoveredParticipant` and :class:`DiscoveredEndpoint` values.

A read that Cyclone refuses (the participant is closing) is logged at debug level and reads as nothing; a
reader that cannot be created is a :class:`~micros_rt.exceptions.TransportError`.
"""

from __future__ import annotations

import threading
import uuid
from typing import Any, Callable, Dict, Iterable, List, NamedTuple, Optional, Tuple

from ...cyclone import import_cyclonedds
from ...exceptions import TransportError
from ...log import nonblocking_logger
from .tags import parse_user_data

__all__ = ["DiscoveredEndpoint", "DiscoveredParticipant", "Discovery", "NodeAnnouncements", "AnnouncedNode",
           "guid_of"]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: samples read at once from a built-in topic: more endpoints than any domain here has
_READ_MAX = 10000


class DiscoveredParticipant(NamedTuple):
    guid: str
    user_data: Optional[bytes]


class DiscoveredEndpoint(NamedTuple):
    """A writer or reader alive on the domain."""

    guid: str
    participant: str
    topic: str            #: DDS topic name, e.g. rt/chatter
    type_name: str        #: DDS type name, e.g. std_msgs::msg::dds_::String_
    user_data: Optional[bytes]
    durability: str       #: Cyclone's policy name: Volatile, TransientLocal, Transient, Persistent ("": not given)
    reliability: str      #: Reliable, BestEffort ("": not given)

    @property
    def tag(self) -> Optional[Dict[str, str]]:
        """micros_rt's tag in its user data; None: not a micros_rt endpoint (a ROS 2 node's)."""
        return parse_user_data(self.user_data)

    @property
    def transient_local(self) -> bool:
        return self.durability in ("TransientLocal", "Transient", "Persistent")

    @property
    def best_effort(self) -> bool:
        return self.reliability == "BestEffort"


def _user_data(qos: Any, policy: Any) -> Optional[bytes]:
    try:
        return bytes(qos[policy.Userdata].data)
    except (KeyError, AttributeError, TypeError):
        return None


def _policy_name(qos: Any, policy: Any) -> str:
    try:
        return type(qos[policy]).__name__.rpartition(".")[2]
    except (KeyError, TypeError):
        return ""


class Discovery:
    """What the participant ``dp`` (a Cyclone DomainParticipant) has discovered. Thread-safe. ``kinds`` opens those
    built-in readers now ("participants", "writers", "readers"); the others open on first use."""

    def __init__(self, dp: Any, kinds: Iterable[str] = (), *, on_change: Optional[Callable[[], None]] = None) -> None:
        import_cyclonedds()
        self._dp = dp
        self._lock = threading.Lock()
        self._readers: Dict[str, Tuple[Any, Any]] = {}
        self._on_change = on_change  # called (on Cyclone's thread) when discovery brings something
        self._followed: Dict[str, Dict[str, Tuple[str, str]]] = {}
        self._participants: Dict[str, DiscoveredParticipant] = {}  # followed_participants()
        for kind in kinds:
            self._reader(kind)

    def _reader(self, kind: str) -> Tuple[Any, Any]:
        found = self._readers.get(kind)
        if found is None:
            import_cyclonedds()
            from cyclonedds.builtin import (BuiltinDataReader, BuiltinTopicDcpsParticipant,
                                            BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription)
            from cyclonedds.core import DDSException, InstanceState, ReadCondition, SampleState, ViewState

            topic = {"participants": BuiltinTopicDcpsParticipant, "writers": BuiltinTopicDcpsPublication,
                     "readers": BuiltinTopicDcpsSubscription}[kind.partition(":")[0]]  # "<kind>:<use>": one more
            try:
                if self._on_change is None:
                    reader = BuiltinDataReader(self._dp, topic)
                else:
                    from cyclonedds.core import Listener

                    wake = self._on_change
                    reader = BuiltinDataReader(self._dp, topic, listener=Listener(  # type: ignore[no-untyped-call]
                        on_data_available=lambda _r: wake()))
                # alive now: a deleted endpoint's sample stays in the reader, its instance disposed
                found = (reader, ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Alive))
            except DDSException as exc:
                raise TransportError(f"cannot read DDS discovery ({kind}): {exc}") from exc
            self._readers[kind] = found
        return found

    def _read(self, kind: str) -> List[Any]:
        import_cyclonedds()
        from cyclonedds.core import DDSException

        with self._lock:
            reader, alive = self._reader(kind)
            try:
                return list(reader.read(N=_READ_MAX, condition=alive))
            except DDSException as exc:
                _log.debug("micros_rt: reading DDS discovery (%s): %s", kind, exc)
                return []

    def participants(self) -> List[DiscoveredParticipant]:
        """The participants alive on the domain (this one included)."""
        import_cyclonedds()
        from cyclonedds.qos import Policy

        return [DiscoveredParticipant(str(p.key), _user_data(p.qos, Policy)) for p in self._read("participants")]

    def followed_participants(self) -> List[DiscoveredParticipant]:
        """The participants alive, kept up to date from the samples discovery brought since the last call: each is
        deserialised once (:meth:`participants` deserialises every participant's sample, QoS included, on every
        call: 62 us a call with one participant on the domain, the host's watcher calling it twice a second). It
        takes the samples from a built-in reader of its own, so :meth:`participants` still sees everything."""
        import_cyclonedds()
        from cyclonedds.core import DDSException, InstanceState
        from cyclonedds.qos import Policy

        with self._lock:
            reader, _alive = self._reader("participants:followed")
            known = self._participants
            try:
                for p in reader.take(N=_READ_MAX):
                    info = p.sample_info
                    key = str(p.key)
                    if info.instance_state == InstanceState.Alive and info.valid_data:
                        known[key] = DiscoveredParticipant(key, _user_data(p.qos, Policy))
                    else:  # disposed or without writers: the participant left
                        known.pop(key, None)
            except DDSException as exc:
                _log.debug("micros_rt: reading DDS discovery (participants): %s", exc)
            return list(known.values())

    def writers(self, dds_topic: Optional[str] = None) -> List[DiscoveredEndpoint]:
        """The writers alive (of ``dds_topic`` only, when given)."""
        return self._endpoints("writers", dds_topic)

    def readers(self, dds_topic: Optional[str] = None) -> List[DiscoveredEndpoint]:
        """The readers alive (of ``dds_topic`` only, when given)."""
        return self._endpoints("readers", dds_topic)

    def followed_topics(self, kind: str) -> Dict[str, Tuple[str, str]]:
        """The writers (``kind="writers"``) or readers alive: GUID -> (participant GUID, DDS topic), kept up to date
        from what discovery brought since the last call. It *takes* the samples (each is deserialised once, not on
        every call: the host's ROS 2 gateway asks on every tick beside hundreds of endpoints), so a Discovery whose
        kind is followed answers :meth:`writers`/:meth:`readers` of that kind with what came since."""
        import_cyclonedds()
        from cyclonedds.core import DDSException, InstanceState

        with self._lock:
            reader, _alive = self._reader(kind)
            known = self._followed.setdefault(kind, {})
            try:
                for e in reader.take(N=_READ_MAX):
                    info = e.sample_info
                    if info.instance_state == InstanceState.Alive and info.valid_data:
                        known[str(e.key)] = (str(e.participant_key), str(e.topic_name))
                    else:
                        known.pop(str(e.key), None)
            except DDSException as exc:
                _log.debug("micros_rt: reading DDS discovery (%s): %s", kind, exc)
            return dict(known)

    def close(self) -> None:
        """Delete the built-in readers now (not with the participant)."""
        from .participant import delete_entity

        with self._lock:
            readers, self._readers = list(self._readers.values()), {}
            self._participants = {}
            self._followed = {}
        for reader, _alive in readers:
            delete_entity(reader)

    def _endpoints(self, kind: str, dds_topic: Optional[str]) -> List[DiscoveredEndpoint]:
        import_cyclonedds()
        from cyclonedds.qos import Policy

        out: List[DiscoveredEndpoint] = []
        for endpoint in self._read(kind):
            topic = getattr(endpoint, "topic_name", None)
            if dds_topic is not None and topic != dds_topic:
                continue
            qos = endpoint.qos
            out.append(DiscoveredEndpoint(str(endpoint.key), str(endpoint.participant_key), str(topic),
                                          str(endpoint.type_name), _user_data(qos, Policy),
                                          _policy_name(qos, Policy.Durability), _policy_name(qos, Policy.Reliability)))
        return out


def guid_of(data: Any) -> str:
    """A GID's 16 bytes (ROS 2's ``rmw_dds_common/Gid``) as the GUID text Cyclone gives its endpoints."""
    return str(uuid.UUID(bytes=bytes(bytearray(int(b) & 0xFF for b in data))))


class AnnouncedNode(NamedTuple):
    participant: str
    namespace: str
    name: str
    readers: List[str]
    writers: List[str]


class NodeAnnouncements:
    """ROS 2's ``ros_discovery_info`` as ``ros2 node list`` reads it: each participant's last announcement of its
    nodes (rmw's QoS: reliable, transient local, so each writer's last sample reaches a late reader). Call
    :meth:`take` to read what came."""

    def __init__(self, dp: Any) -> None:
        import_cyclonedds()
        from cyclonedds.core import DDSException, Policy, Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from .ros2_graph import TOPIC, ParticipantEntitiesInfo

        # all samples kept: the topic has no key and every participant writes to the one instance
        qos = Qos(Policy.Reliability.Reliable(max_blocking_time=0), Policy.Durability.TransientLocal,
                  Policy.History.KeepAll)
        try:
            self._reader = DataReader(dp, Topic(dp, TOPIC, ParticipantEntitiesInfo, qos=qos), qos=qos)
        except DDSException as exc:
            raise TransportError(f"cannot read ROS 2's {TOPIC}: {exc}") from exc
        self.topic = TOPIC
        self._latest: Dict[str, Any] = {}   # participant GID -> its last announcement (samples come in arrival order)

    def take(self) -> None:
        """Take the announcements that came since the last call."""
        import_cyclonedds()
        from cyclonedds.core import DDSException

        try:
            samples = self._reader.take(N=_READ_MAX)
        except DDSException as exc:
            _log.debug("micros_rt: reading ros_discovery_info: %s", exc)
            return
        for sample in samples:
            info = getattr(sample, "sample_info", None)
            if info is None or info.valid_data:
                self._latest[guid_of(sample.gid.data)] = sample

    def announced(self) -> List[str]:
        """GIDs of the participants whose announcement has come."""
        return list(self._latest)

    def nodes(self) -> List[AnnouncedNode]:
        """Every node of every announcement, by participant GID."""
        return [AnnouncedNode(gid, str(node.node_namespace), str(node.node_name),
                              [guid_of(g.data) for g in node.reader_gid_seq],
                              [guid_of(g.data) for g in node.writer_gid_seq])
                for gid, sample in sorted(self._latest.items()) for node in sample.node_entities_info_seq]
