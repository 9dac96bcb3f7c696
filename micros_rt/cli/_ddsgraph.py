"""The ROS 2 side of the graph as DDS discovery shows it, for ``micros-rt topic list`` and ``node list``.

A short-lived Cyclone participant, started with micros_rt's own configuration
(:func:`micros_rt.transports.dds.participant.cyclone_config`: loopback only when ``ROS_IP``/``ROS_HOSTNAME`` is
loopback, ``CYCLONEDDS_URI`` when set) on ``ROS_DOMAIN_ID``, listens for a bounded time and reads:

- DDS discovery (:mod:`micros_rt.transports.dds.discovery`, the one reader of it): every reader and writer of the domain, its DDS
  topic and type names and its USER_DATA, where micros_rt endpoints carry their tag (``micros_rt;graph=...;
  node=...;``, :func:`micros_rt.transports.dds.endpoints.parse_user_data`). Endpoints without it belong to
  other DDS programs: ROS 2 nodes.
- ROS 2's ``ros_discovery_info`` topic (``rmw_dds_common/msg/ParticipantEntitiesInfo``, the type micros_rt
  announces its own nodes with, :mod:`micros_rt.transports.dds.ros2_graph`; read by the same module): per participant, its nodes and the
  GIDs of their readers and writers. That is how ``ros2 node list`` names nodes, and how this module does.

The participant announces nothing (no ``ros_discovery_info`` of its own), so ROS 2 tools do not list it as a node.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Set

from .. import settings
from ..cyclone import import_cyclonedds

__all__ = ["DEFAULT_WAIT", "NAMES_WAIT", "DdsEndpoint", "DdsView", "Ros2Node", "discover", "ros2_type_name"]

#: Seconds of discovery before the ROS 2 side is read (``--wait``). On one host a new participant finds the
#: others within ~30 ms and learns their readers and writers ~1.1 s later (measured, Cyclone and Fast DDS
#: peers on loopback); a peer across a network may need longer.
DEFAULT_WAIT = 1.5
#: Seconds more, at most, for the ``ros_discovery_info`` of participants that have not sent it yet (what names
#: ROS 2 nodes): a Fast DDS (rclpy) participant's reaches a new reader only with its writer's next periodic
#: heartbeat, ~3 s after the match (measured: 3.0 s every time); Cyclone's (micros_rt) at once.
NAMES_WAIT = 3.5


@dataclass
class DdsEndpoint:
    """A reader or writer discovered on the domain."""

    guid: str
    participant: str
    topic: str            # DDS topic name, e.g. rt/chatter
    type_name: str        # DDS type name, e.g. std_msgs::msg::dds_::String_
    writer: bool
    tag: Optional[Dict[str, str]]  # micros_rt's USER_DATA tag; None: not a micros_rt endpoint
    #: its QoS as discovery carries it: reliable (else best effort) and transient_local (else volatile); None when
    #: not announced
    reliable: Optional[bool] = None
    transient_local: Optional[bool] = None

    def qos_text(self) -> str:
        """``reliable, volatile``-style words, as ``ros2 topic info -v`` names the two policies."""
        words = ["?" if self.reliable is None else "reliable" if self.reliable else "best effort",
                 "?" if self.transient_local is None else "transient_local" if self.transient_local else "volatile"]
        return ", ".join(words)


@dataclass
class Ros2Node:
    """A node as a participant's ``ros_discovery_info`` announces it."""

    namespace: str
    name: str
    participant: str
    readers: List[str] = field(default_factory=list)
    writers: List[str] = field(default_factory=list)

    @property
    def full_name(self) -> str:
        """``/ns/name`` as ROS 1 and ``ros2 node list`` spell it."""
        ns = self.namespace.rstrip("/")
        return f"{ns}/{self.name}" if ns else f"/{self.name}"


@dataclass
class DdsView:
    """What discovery showed; ``available`` False with ``note`` saying why when DDS could not be used."""

    available: bool
    note: str = ""
    domain: Optional[int] = None
    wait: float = 0.0
    participants: Set[str] = field(default_factory=set)
    endpoints: List[DdsEndpoint] = field(default_factory=list)
    nodes: List[Ros2Node] = field(default_factory=list)
    #: participants with a ``ros_discovery_info`` writer whose announcement had not come (their nodes unnamed)
    unnamed: Set[str] = field(default_factory=set)
    #: participants of micros_rt's own rclpy helpers (services and actions toward ROS 2: ROS 2 enclave
    #: ``/micros_rt`` in their user data), whose nodes are ``<ROS 1 node>_services``/``_actions``
    helpers: Set[str] = field(default_factory=set)

    def owners(self) -> Dict[str, Ros2Node]:
        """Endpoint GUID -> the ROS 2 node that announced it."""
        return {guid: node for node in self.nodes for guid in node.readers + node.writers}


def ros2_type_name(dds_type: str) -> str:
    """ROS 2's name of a DDS type name: ``std_msgs::msg::dds_::String_`` -> ``std_msgs/msg/String``; a name
    that is not a ROS 2 type's stays as it is.

    >>> ros2_type_name("std_msgs::msg::dds_::String_"), ros2_type_name("Plain")
    ('std_msgs/msg/String', 'Plain')
    """
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_type


def _is_helper(user_data: Optional[bytes]) -> bool:
    """Whether a participant's user data is one of micros_rt's rclpy helpers' (not a micros_rt node's)."""
    from ..transports.dds.watch import is_micros_rt_participant

    return is_micros_rt_participant(user_data) and b"micros_rt=1;" not in bytes(user_data or b"")


def discover(wait: float = DEFAULT_WAIT, env: Mapping[str, str] = os.environ, *, names: bool = True,
             names_wait: float = NAMES_WAIT, name_topics: Optional[Set[str]] = None) -> DdsView:
    """Join ``ROS_DOMAIN_ID`` with micros_rt's Cyclone configuration for ``wait`` seconds and return what it
    saw; with ``names``, then up to ``names_wait`` seconds more until every participant that announces its
    nodes on ``ros_discovery_info`` has been heard (only those with a reader or writer of one of the DDS topics
    ``name_topics`` when given). Never raises for a DDS that cannot start: the view then says why (``available``
    False)."""
    if settings.DISABLE_DDS.get(env):
        return DdsView(False, "DDS is disabled (MICROS_RT_DISABLE_DDS is set)")
    try:
        import_cyclonedds()
        from ..exceptions import MicrosRtError
        from ..transports.dds.discovery import Discovery, NodeAnnouncements
        from ..transports.dds.participant import DDSParticipant, cyclone_config, domain_id_from_env
    except ImportError as exc:
        return DdsView(False, f"Cyclone DDS cannot be imported ({exc}); run scripts/setup.sh")
    try:
        domain = domain_id_from_env(env)
        participant = DDSParticipant(domain, cyclone_config(env))
    except (MicrosRtError, OSError) as exc:
        return DdsView(False, f"{exc}. Check ROS_DOMAIN_ID, CYCLONEDDS_URI and ROS_IP (micros-rt doctor checks them)")
    view = DdsView(True, domain=domain, wait=wait)
    try:
        discovery = Discovery(participant.dp, kinds=("participants", "writers", "readers"))
        announcements = NodeAnnouncements(participant.dp)
        own = participant.guid

        start = time.monotonic()
        time.sleep(max(0.0, wait))
        deadline = start + wait + names_wait
        while True:
            announcements.take()
            if not names:
                break
            announcing = {e.participant for e in discovery.writers(announcements.topic) if e.participant != own}
            if name_topics is not None:
                announcing &= {e.participant for e in discovery.writers() + discovery.readers()
                               if e.topic in name_topics}
            view.unnamed = announcing - set(announcements.announced())
            if not view.unnamed or time.monotonic() >= deadline:
                break
            time.sleep(0.1)
        view.wait = round(time.monotonic() - start, 2)

        found_participants = discovery.participants()
        view.participants = {p.guid for p in found_participants} - {own}
        view.helpers = {p.guid for p in found_participants if _is_helper(p.user_data)} - {own}
        for found, is_writer in ((discovery.writers(), True), (discovery.readers(), False)):
            for ep in found:
                if ep.participant == own:
                    continue
                view.endpoints.append(DdsEndpoint(
                    ep.guid, ep.participant, ep.topic, ep.type_name, is_writer, ep.tag,
                    ep.reliability == "Reliable" if ep.reliability else None,
                    ep.durability in ("TransientLocal", "Transient", "Persistent") if ep.durability else None))
        for node in announcements.nodes():
            if node.participant not in view.participants:
                continue  # a participant that has left since it wrote
            view.nodes.append(Ros2Node(node.namespace, node.name, node.participant, node.readers, node.writers))
    except MicrosRtError as exc:
        return DdsView(False, f"Cyclone DDS failed while reading discovery on domain {domain} ({exc})")
    finally:
        participant.close()
    return view
