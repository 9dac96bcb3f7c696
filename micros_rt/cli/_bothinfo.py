"""One topic in both worlds, for ``micros-rt topic info`` and ``micros-rt graph``: its ROS 2 endpoints (DDS discovery,
:mod:`._ddsgraph`), the DDS links between them and this graph's micros_rt nodes, and what a ``micros-rt relay``'s
``ros2:`` section carries between ROS 1 and ROS 2 (its ``microsRtInfo`` ``relay`` section, and the tags of its DDS
writers and readers). Pure functions over what :func:`._ddsgraph.discover` and :func:`._graphinfo.probe_node`
collected.

Who an endpoint of ``rt/<topic>`` belongs to (:func:`dds_endpoints`):

- ``micros_rt``: a micros_rt node of this graph (its tag names the node); its ROS 1 endpoint is the same one;
- ``relay``: a relay of this graph writing what it carries to ROS 2 (tag ``relay_ros2``) or reading what it carries
  into ROS 1 (``relay_ros2_import``);
- ``helper``: micros_rt's own rclpy helper of a node (services and actions; ROS 2 enclave ``/micros_rt``);
- ``ROS 2``: a ROS 2 node's, named by its participant's ``ros_discovery_info``.
"""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

from ._ddsgraph import DdsEndpoint, DdsView, ros2_type_name
from ._graphinfo import NodeReport

__all__ = ["ACTION_TOPICS", "carriage", "dds_endpoints", "dds_links", "dds_match", "describe_carriage",
           "ros2_entries"]

MICROS_RT, RELAY, HELPER, ROS2 = "micros_rt", "relay", "helper", "ROS 2"
#: The topics of a ROS 1 (actionlib) action ``<name>``.
ACTION_TOPICS = ("goal", "cancel", "status", "feedback", "result")


def dds_topic(topic: str) -> str:
    """``/a/b`` -> ``rt/a/b``."""
    return "rt/" + topic.lstrip("/")


def ros2_entries(report: Optional[NodeReport]) -> List[Dict[str, Any]]:
    """The ``ros2:`` entries a relay node carries (its ``relay`` section's ``ros2`` list: ``direction``, ``kind``,
    ``name``, ``as`` and counters); empty for any other node."""
    section = report.relay() if report is not None else None
    return [dict(e) for e in (section or {}).get("ros2") or [] if isinstance(e, dict) and e.get("kind")]


def _ros1_name(entry: Mapping[str, Any]) -> str:
    return str(entry.get("name") if entry.get("direction") == "export" else entry.get("as"))


def _ros2_name(entry: Mapping[str, Any]) -> str:
    return str(entry.get("as") if entry.get("direction") == "export" else entry.get("name"))


def carriage(reports: Mapping[str, NodeReport], topic: str) -> List[Dict[str, Any]]:
    """What relays carry of ``topic`` between ROS 1 and ROS 2, as a ROS 1 name or a ROS 2 name: a topic entry of that
    name, or an action entry whose topics it is one of. Each with ``relay`` (node), ``direction`` (``to ROS 2`` or
    ``from ROS 2``), ``kind``, ``ros1``/``ros2`` names, ``counters`` and a ``description`` in words."""
    out = []
    for node, report in sorted(reports.items()):
        for entry in ros2_entries(report):
            ros1, ros2 = _ros1_name(entry), _ros2_name(entry)
            names = {ros1, ros2}
            if entry["kind"] == "action":
                names = {f"{n}/{t}" for n in names for t in ACTION_TOPICS}
            if topic not in names:
                continue
            out.append({"relay": node, "direction": "to ROS 2" if entry["direction"] == "export" else "from ROS 2",
                        "kind": entry["kind"], "ros1": ros1, "ros2": ros2, "counters": entry,
                        "description": describe_carriage(node, entry)})
    return out


def describe_carriage(node: str, entry: Mapping[str, Any]) -> str:
    """A relay's ``ros2:`` entry in words.

    >>> describe_carriage("/relay_robot", {"direction": "export", "kind": "topic", "name": "/chatter",
    ...                                    "as": "/chatter", "received": 9, "sent": 9, "no_reader": 0})
    'carried to ROS 2 as /chatter by relay node /relay_robot: sent 9 of 9 received'
    >>> describe_carriage("/relay_robot", {"direction": "import", "kind": "topic", "name": "/odom", "as": "/odom",
    ...                                    "received": 5, "published": 5, "latch": True})
    'carried from ROS 2 (its /odom) into ROS 1 by relay node /relay_robot, latched: published 5 of 5 received'
    """
    kind, ros1, ros2 = str(entry.get("kind")), _ros1_name(entry), _ros2_name(entry)
    what = "" if kind == "topic" else f"{kind} "
    latched = ", latched" if entry.get("latch") else ""
    if entry.get("direction") == "export":
        text = f"{what}carried to ROS 2 as {ros2} by relay node {node}{latched}"
        if kind == "topic":
            dropped = [f"{k.replace('_', ' ')} {entry[k]}" for k in ("no_reader", "rate_capped", "superseded",
                                                                       "dropped_queue_full") if entry.get(k)]
            text += f": sent {entry.get('sent', 0)} of {entry.get('received', 0)} received" + (
                f" ({', '.join(dropped)})" if dropped else "")
    else:
        text = f"{what}carried from ROS 2 (its {ros2}) into ROS 1{'' if ros1 == ros2 else ' as ' + ros1} by relay " \
               f"node {node}{latched}"
        if kind == "topic":
            text += f": published {entry.get('published', 0)} of {entry.get('received', 0)} received"
    if kind == "service":
        text += f": {entry.get('calls', 0)} calls, {entry.get('failed', 0)} failed"
    elif kind == "action":
        text += f": {entry.get('goals', 0)} goals, {entry.get('succeeded', 0)} succeeded"
    return text


def _owner(ep: DdsEndpoint, view: DdsView, owners: Mapping[str, Any]) -> str:
    node = owners.get(ep.guid)
    return node.full_name if node is not None else f"? (participant {ep.participant})"


def dds_endpoints(view: DdsView, topic: str, ours: Callable[[Mapping[str, str]], bool]) -> List[Dict[str, Any]]:
    """The readers and writers of ``rt/<topic>`` (other ROS 1 graphs' left out), each with ``node``, ``kind``
    (micros_rt, relay, helper, ROS 2), ``writer``, ``type`` (ROS 2's name), ``reliable``, ``transient_local``,
    ``qos`` in words and its ``guid``."""
    owners = view.owners()
    out = []
    for ep in view.endpoints:
        if ep.topic != dds_topic(topic):
            continue
        if ep.tag is not None:
            if not ours(ep.tag):
                continue
            node = ep.tag.get("node", "?")
            kind = RELAY if ("relay_ros2" in ep.tag or "relay_ros2_import" in ep.tag) else MICROS_RT
        else:
            node = _owner(ep, view, owners)
            kind = HELPER if ep.participant in view.helpers else ROS2
        out.append({"node": node, "kind": kind, "writer": ep.writer, "type": ros2_type_name(ep.type_name),
                    "reliable": ep.reliable, "transient_local": ep.transient_local, "qos": ep.qos_text(),
                    "guid": ep.guid})
    return sorted(out, key=lambda e: (not e["writer"], e["kind"] != ROS2, e["node"], e["guid"]))


def dds_match(writer: Mapping[str, Any], reader: Mapping[str, Any]) -> Optional[str]:
    """Why a DDS writer and reader of one topic do not match (the two policies ROS 2 endpoints differ in), None when
    they do.

    >>> dds_match({"reliable": False, "transient_local": False}, {"reliable": True, "transient_local": False})
    'the writer is best effort, the reader requires reliable'
    >>> dds_match({"reliable": True, "transient_local": False}, {"reliable": True, "transient_local": True})
    'the writer is volatile, the reader requires transient_local'
    """
    if writer.get("reliable") is False and reader.get("reliable"):
        return "the writer is best effort, the reader requires reliable"
    if writer.get("transient_local") is False and reader.get("transient_local"):
        return "the writer is volatile, the reader requires transient_local"
    if writer.get("type") != reader.get("type"):
        return f"the writer's type is {writer.get('type')}, the reader's {reader.get('type')}"
    return None


def dds_links(endpoints: Sequence[Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """The DDS links of a topic with a ROS 2 node (or a helper) at one end at least: every writer to every reader,
    each with ``publisher``, ``subscriber``, their kinds, ``matched`` (by the policies) and ``reason`` when not.
    Links between two micros_rt nodes are ROS 1 links (``getBusInfo``) and left out here, as are a relay's own
    writer and reader of one name (it never reads back what it writes)."""
    links = []
    for w in (e for e in endpoints if e["writer"]):
        for r in (e for e in endpoints if not e["writer"]):
            if w["kind"] not in (ROS2, HELPER) and r["kind"] not in (ROS2, HELPER):
                continue
            reason = dds_match(w, r)
            links.append({"publisher": w["node"], "publisher_kind": w["kind"], "subscriber": r["node"],
                          "subscriber_kind": r["kind"], "protocol": "DDS", "matched": reason is None,
                          "reason": reason})
    return links


def endpoint_words(ep: Mapping[str, Any], carried: Sequence[Mapping[str, Any]]) -> str:
    """A DDS endpoint's ``[kind]`` and what it is, for ``topic info``'s ROS 2 lines."""
    if ep["kind"] == RELAY:
        ways = [c for c in carried if c["relay"] == ep["node"]]
        how = (f"writes ROS 1's {ways[0]['ros1']} for ROS 2" if ep["writer"] and ways else
               f"reads it into ROS 1 as {ways[0]['ros1']}" if ways else
               "writes it for ROS 2" if ep["writer"] else "reads it into ROS 1")
        return f"[relay] {how}; {ep['qos']}"
    if ep["kind"] == MICROS_RT:
        return f"[micros_rt] this graph's ROS 1 node, on DDS too; {ep['qos']}"
    if ep["kind"] == HELPER:
        return f"[micros_rt helper] a micros_rt node's rclpy helper; {ep['qos']}"
    return f"[ROS 2] {ep['type']}; {ep['qos']}"
