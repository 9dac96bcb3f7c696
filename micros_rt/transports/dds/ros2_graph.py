"""Announce this ROS 1 node to ROS 2's graph (``ros_discovery_info``), so ROS 2 tools name it.

ROS 2 maps DDS endpoints to node names through the ``ros_discovery_info`` topic: each
participant publishes which nodes it hosts and the GIDs (DDS GUIDs) of their readers and
writers. Without it, ``ros2 node list`` misses micros_rt nodes and ``ros2 topic info -v``
shows their endpoints as ``_CREATED_BY_BARE_DDS_APP_``. With it, a micros_rt talker is
``/talker`` to ROS 2 as it is to ROS 1.
"""

from __future__ import annotations

import logging
import threading
import uuid
from typing import Any, Set, Tuple

from ...cyclone import import_cyclonedds
import_cyclonedds()
from cyclonedds.idl import make_idl_struct
from cyclonedds.idl import types as _t
from ...log import nonblocking_logger

__all__ = ["Ros2GraphAnnouncer", "split_node_name"]

_log = nonblocking_logger("rosout.micros_rt.dds")

TOPIC = "ros_discovery_info"

t: Any = _t  # cyclonedds' IDL type constructors are not typed for mypy
# rmw_dds_common/msg (ROS 2 Jazzy): Gid is uint8[16]
Gid: Any = make_idl_struct("Gid", "rmw_dds_common::msg::dds_::Gid_", {"data": t.array[t.uint8, 16]})
NodeEntitiesInfo: Any = make_idl_struct("NodeEntitiesInfo", "rmw_dds_common::msg::dds_::NodeEntitiesInfo_", {
    "node_namespace": t.bounded_str[256],
    "node_name": t.bounded_str[256],
    "reader_gid_seq": t.sequence[Gid],
    "writer_gid_seq": t.sequence[Gid],
})
ParticipantEntitiesInfo: Any = make_idl_struct(
    "ParticipantEntitiesInfo", "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_",
    {"gid": Gid, "node_entities_info_seq": t.sequence[NodeEntitiesInfo]})


def split_node_name(caller_id: str) -> Tuple[str, str]:
    """ROS 1 node name to ROS 2 (namespace, name): ``/robot1/talker`` -> ``('/robot1', 'talker')``."""
    ns, _, name = caller_id.rstrip("/").rpartition("/")
    return (ns or "/"), name


def _gid(guid: str) -> Any:
    return Gid(data=list(uuid.UUID(guid).bytes))


class Ros2GraphAnnouncer:
    """Publishes this process's node and its endpoints on ``ros_discovery_info`` (latched)."""

    def __init__(self, participant: Any, caller_id: str) -> None:
        import_cyclonedds()
        from cyclonedds.core import Policy, Qos
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        self.participant = participant
        self._participant_gid = _gid(participant.guid)
        self._namespace, self._name = split_node_name(caller_id)
        self._readers: Set[str] = set()
        self._writers: Set[str] = set()
        self._lock = threading.Lock()
        # the QoS rmw uses for this topic: reliable, transient local, the last sample per writer
        qos = Qos(Policy.Reliability.Reliable(max_blocking_time=0), Policy.Durability.TransientLocal,
                  Policy.History.KeepLast(1))
        topic = Topic(participant.dp, TOPIC, ParticipantEntitiesInfo, qos=qos)
        self._writer = DataWriter(participant.dp, topic, qos)
        self._publish()

    def _publish(self) -> None:
        with self._lock:
            node = NodeEntitiesInfo(node_namespace=self._namespace, node_name=self._name,
                                    reader_gid_seq=[_gid(g) for g in sorted(self._readers)],
                                    writer_gid_seq=[_gid(g) for g in sorted(self._writers)])
            sample = ParticipantEntitiesInfo(gid=self._participant_gid, node_entities_info_seq=[node])
            try:
                self._writer.write(sample)
            except Exception as exc:  # the ROS 2 graph view is a courtesy; data must flow regardless
                _log.debug("micros_rt: cannot announce the node to ROS 2 (%s)", exc)

    def update(self, *, add_reader: str = "", add_writer: str = "", remove: str = "") -> None:
        """Record an endpoint created or deleted, and announce the new set."""
        with self._lock:
            if add_reader:
                self._readers.add(add_reader)
            if add_writer:
                self._writers.add(add_writer)
            if remove:
                self._readers.discard(remove)
                self._writers.discard(remove)
        self._publish()
