"""One DDS presence per host for ROS 2's graph (``auto`` visibility): the host's watcher (:mod:`.watch`) stands in
for every micros_rt node of its host, Unix user and DDS domain that no ROS 2 node exchanges data with.

Each node under ``auto`` describes its endpoints in a small file (:func:`write_description`: topic, type and its
definition, queue, latch, QoS options, tag), written when its topics change. While a participant that is not
micros_rt's is on the domain, the watcher's :class:`HostGateway` holds, on one participant of its own, a DDS
writer or reader per endpoint of those nodes with the endpoint's QoS and tag (a *proxy*), and announces every
node under its own name with its proxies' GIDs on ``ros_discovery_info`` (one ``ParticipantEntitiesInfo``, several
nodes in ``node_entities_info_seq``). ``ros2 node list``, ``ros2 topic list``, ``ros2 topic info -v`` and rclpy's
graph calls so show the host's nodes and endpoints as when each node had its own participant.

The proxies live in a DDS partition of their own (:data:`PROXY_PARTITION`): discovery carries them to every
graph, but they match no reader or writer, so they never carry or take data. A node becomes visible itself (its
own participant, writers and readers, as with ``MICROS_RT_ROS2=on``) only when a ROS 2 endpoint is on one of its
topics, in the other direction: a ROS 2 reader of what it publishes, a ROS 2 writer of what it subscribes to.
The gateway then names it in the *visible* file (``<pid> <node>`` lines), the node sees its line on its next
housekeeping tick, and the gateway drops the node's proxies and announcement. A node that became visible stays
so, as before.

What it costs: nodes with no ROS 2 peer of their topics keep no participant while an idle ROS 2 node, the
``ros2`` daemon or a tool is on the domain; the watcher adds one participant and a Cyclone entity per endpoint of
the host, which carry no data.
"""

from __future__ import annotations

import json
import os
import threading
import time
import uuid
from typing import Any, Dict, FrozenSet, List, Mapping, NamedTuple, Optional, Sequence, Set, Tuple

from ...cyclone import import_cyclonedds
from ...log import nonblocking_logger
from ...negotiation.protocol import DDS

__all__ = ["PROXY_PARTITION", "WAKE", "EndpointDescription", "HostGateway", "NodeDescription", "endpoint_descriptions",
           "named_visible", "prune_descriptions", "read_visible", "remove_description", "write_description"]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: Seconds of a watcher's tick spent making proxies at most (a new type costs Cyclone tens of milliseconds): a host
#: of many nodes is announced over a few ticks, and nodes a ROS 2 endpoint talks to are named on every tick
PROXY_BUDGET = 0.15

#: Set when DDS discovery brings a new endpoint: the watcher's housekeeping tick runs sooner than its period
WAKE = threading.Event()

#: The DDS partition of the gateway's proxies: ROS 2 uses the default partition only, so nothing matches them
PROXY_PARTITION = "micros_rt_host_gateway"


class EndpointDescription(NamedTuple):
    """One endpoint of a node, as its description file says it."""

    kind: str                         # "pub" or "sub"
    topic: str                        # ROS name
    type: str                         # ROS 1 type, ``pkg/Name``
    md5: str
    definition: str                   # the type's full definition (genpy's ``_full_text``)
    queue_size: Optional[int]
    latch: bool
    options: Optional[Dict[str, Any]]  # the QoS options' ``to_dict()``; None: a plain subscriber
    tag: Dict[str, str]


class NodeDescription(NamedTuple):
    pid: int
    node: str
    endpoints: Tuple[EndpointDescription, ...]
    text: str = ""   # the file's text

    def keys(self) -> List[str]:
        """Each endpoint's identity (:func:`_key`), made once per description."""
        return _keys(self)

    @classmethod
    def parse(cls, text: str) -> "NodeDescription":
        raw = json.loads(text)
        return cls(int(raw["pid"]), str(raw["node"]), tuple(
            EndpointDescription(str(e["kind"]), str(e["topic"]), str(e["type"]), str(e["md5"]), str(e["definition"]),
                                None if e["queue_size"] is None else int(e["queue_size"]), bool(e["latch"]),
                                e["options"], {str(k): str(v) for k, v in e["tag"].items()})
            for e in raw["endpoints"]), text)


def _description_path(prefix: str, pid: int) -> str:
    return f"{prefix}{pid}.json"


def write_description(prefix: str, node: str, endpoints: List[EndpointDescription]) -> None:
    """This process's node and endpoints, for the host's gateway (atomically: it reads a whole file or none), in
    ``<prefix><pid>.json`` (beside the watcher's lock and marker)."""
    path = _description_path(prefix, os.getpid())
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        json.dump({"pid": os.getpid(), "node": node, "endpoints": [e._asdict() for e in endpoints]}, f)
    os.replace(tmp, path)


def remove_description(prefix: str) -> None:
    try:
        os.unlink(_description_path(prefix, os.getpid()))
    except OSError:
        pass


def prune_descriptions(prefix: str) -> None:
    """Remove the description files of processes that are gone (killed: a node that shuts down removes its own),
    and the half-written ones they left (``.json.tmp``: killed between :func:`write_description`'s open and rename;
    seen in /dev/shm after a 60-node ring was killed)."""
    directory, base = os.path.split(prefix)
    try:
        names = [n for n in os.listdir(directory) if n.startswith(base) and n.endswith((".json", ".json.tmp"))]
    except OSError:
        return
    for name in names:
        stem = name[len(base):].split(".", 1)[0]
        if stem.isdigit() and not _alive(int(stem)):
            try:
                os.unlink(os.path.join(directory, name))
            except OSError:
                pass


def read_visible(path: str) -> Dict[int, str]:
    """The visible file: pid -> node name of the nodes the gateway asked to be visible themselves."""
    out: Dict[int, str] = {}
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except OSError:
        return out
    for line in lines:
        pid, _, node = line.partition(" ")
        if pid.isdigit() and node:
            out[int(pid)] = node
    return out


def named_visible(path: str, node: str) -> bool:
    return read_visible(path).get(os.getpid()) == node


_last_described: Tuple[Tuple[int, ...], List[EndpointDescription]] = ((), [])


def endpoint_descriptions(pubs: Sequence[Any], subs: Sequence[Any]) -> List[EndpointDescription]:
    """A node's publications and subscriptions (the core's, from its registries) as its description tells the
    gateway: each that would be a ROS 2 endpoint (a DDS side the node's profile does not refuse), in a stable order;
    made again only when the node's endpoints changed (this runs on every housekeeping tick)."""
    global _last_described
    key = (*(id(p) for p in pubs), *(id(s) for s in subs), *(int(p.closed) for p in pubs),
           *(int(s.closed) for s in subs))
    if key == _last_described[0]:
        return _last_described[1]
    out: List[EndpointDescription] = []
    for pub in pubs:
        side = pub.sides.get(DDS)
        if side is None or side.refusal is not None or pub.closed:
            continue
        cls = pub.data_class
        out.append(EndpointDescription("pub", pub.topic, cls._type, cls._md5sum, str(getattr(cls, "_full_text", "")),
                                       pub.queue_size, bool(pub.latch), pub.options.to_dict(), dict(pub.tag)))
    for sub in subs:
        if sub.sides.get(DDS) is None or sub.closed:
            continue
        cls = sub.data_class
        out.append(EndpointDescription("sub", sub.topic, cls._type, cls._md5sum, str(getattr(cls, "_full_text", "")),
                                       sub.queue_size, False, None if sub.options is None else sub.options.to_dict(),
                                       dict(sub.tag)))
    out.sort(key=lambda e: (e.kind, e.topic))
    _last_described = (key, out)
    return out


def _alive(pid: int) -> bool:
    return os.path.exists(f"/proc/{pid}")


_classes: Dict[Tuple[str, str], Any] = {}  # (type, md5) -> the class the gateway built


def _message_class(endpoint: EndpointDescription) -> Any:
    """The genpy class of the endpoint's type, built from the definition the node sent (a proxy carries no data: a
    class of the same fields is all it needs; roslib would look ~0.7 s for a package that is not installed),
    and made known to the DDS mapping for the nested types."""
    found = _classes.get((endpoint.type, endpoint.md5))
    if found is not None:
        return found
    import genpy.dynamic

    from .types import register_message_classes

    classes = genpy.dynamic.generate_dynamic(endpoint.type, endpoint.definition)
    register_message_classes(classes)
    found = _classes[(endpoint.type, endpoint.md5)] = classes[endpoint.type]
    return found


def _key(e: EndpointDescription) -> str:
    """An endpoint's identity: a proxy is made again when anything of it changed (its QoS, its type)."""
    return json.dumps(e._asdict(), sort_keys=True)


_keys_made: Dict[str, List[str]] = {}  # a description's text -> its endpoints' keys (bounded below)


def _keys(desc: "NodeDescription") -> List[str]:
    found = _keys_made.get(desc.text)
    if found is None:
        if len(_keys_made) > 4096:
            _keys_made.clear()
        found = _keys_made[desc.text] = [_key(e) for e in desc.endpoints]
    return found


def _gid(guid: str) -> Any:
    from .ros2_graph import Gid

    return Gid(data=list(uuid.UUID(guid).bytes))


class HostGateway:
    """The host's proxies and their ``ros_discovery_info`` (see the module's text), on a participant of its own
    beside the watcher's process participant (whose built-in topics tell where ROS 2 endpoints are)."""

    def __init__(self, process_participant: Any, nodes_prefix: str, visible_path: str) -> None:
        import_cyclonedds()
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter, Publisher
        from cyclonedds.sub import Subscriber
        from cyclonedds.topic import Topic

        from .discovery import Discovery
        from .participant import PARTICIPANT_USER_DATA
        from .ros2_graph import TOPIC, ParticipantEntitiesInfo

        self.nodes_prefix = nodes_prefix
        self.visible_path = visible_path
        self.visible: Dict[int, str] = {p: n for p, n in read_visible(visible_path).items() if _alive(p)}
        # a new endpoint on the domain wakes the watcher's tick (a ROS 2 reader of a node's topic: named at once)
        self._discovery = Discovery(process_participant.dp, ("writers", "readers"), on_change=WAKE.set)
        self.dp = DomainParticipant(process_participant.local_id, qos=Qos(Policy.Userdata(PARTICIPANT_USER_DATA)))
        self.guid = str(self.dp.guid)
        partition = Qos(Policy.Partition([PROXY_PARTITION]))
        self._publisher = Publisher(self.dp, qos=partition)
        self._subscriber = Subscriber(self.dp, qos=partition)
        qos = Qos(Policy.Reliability.Reliable(max_blocking_time=0), Policy.Durability.TransientLocal,
                  Policy.History.KeepLast(1))
        self._info = DataWriter(self.dp, Topic(self.dp, TOPIC, ParticipantEntitiesInfo, qos=qos), qos)
        self._topics: Dict[str, Tuple[Any, str]] = {}       # DDS topic -> (Topic, DDS type name)
        self._proxies: Dict[Tuple[int, str], Tuple[Any, str]] = {}  # (pid, endpoint's key) -> (entity, GUID)
        self._described: Dict[int, Tuple[int, NodeDescription]] = {}  # pid -> (file mtime_ns, description)
        self._refused: Set[Tuple[str, str]] = set()  # (topic, why) said once
        self._unmade: Set[Tuple[int, str]] = set()     # proxies that could not be made
        self._announced: Any = None
        self._lock = threading.Lock()
        self.closed = False

    # -- one tick of the watcher, while ROS 2 is on the domain ------------------------------------------------------
    def update(self, foreign: FrozenSet[str]) -> None:
        """Read the host's descriptions, name the nodes a ROS 2 endpoint talks to, keep the others' proxies."""
        with self._lock:
            if self.closed:
                return
            described = self._read_descriptions()
            ros2_readers, ros2_writers = self._ros2_endpoints(foreign)
            from .types import dds_topic_name

            named = False
            for pid, desc in described.items():
                if pid in self.visible:
                    continue
                for e in desc.endpoints:
                    wanted = ros2_readers if e.kind == "pub" else ros2_writers
                    if dds_topic_name(e.topic) in wanted:
                        self.visible[pid] = desc.node
                        named = True
                        _log.info("micros_rt: a ROS 2 %s of %s: node %s makes its topics ROS 2 topics itself",
                                  "reader" if e.kind == "pub" else "writer", e.topic, desc.node)
                        break
            if named:
                self._write_visible()
            self._keep_proxies({pid: d for pid, d in described.items() if pid not in self.visible})

    def _read_descriptions(self) -> Dict[int, NodeDescription]:
        directory, base = os.path.split(self.nodes_prefix)
        try:
            names = [n for n in os.listdir(directory) if n.startswith(base) and n.endswith(".json")]
        except OSError:
            names = []
        seen: Dict[int, NodeDescription] = {}
        for name in names:
            stem = name[len(base):-len(".json")]
            if not stem.isdigit():
                continue
            pid, path = int(stem), os.path.join(directory, name)
            if not _alive(pid):  # a node killed: its file stays until here
                try:
                    os.unlink(path)
                except OSError:
                    pass
                continue
            try:
                mtime = os.stat(path).st_mtime_ns
                known = self._described.get(pid)
                if known is not None and known[0] == mtime:
                    seen[pid] = known[1]
                    continue
                with open(path) as f:
                    desc = NodeDescription.parse(f.read())
            except (OSError, ValueError, KeyError, TypeError) as exc:
                _log.debug("micros_rt: reading %s: %s", path, exc)
                continue
            self._described[pid] = (mtime, desc)
            seen[pid] = desc
        for pid in set(self._described) - set(seen):
            del self._described[pid]
        for pid in [p for p in self.visible if not _alive(p)]:
            del self.visible[pid]
        return seen

    def _ros2_endpoints(self, foreign: FrozenSet[str]) -> Tuple[Set[str], Set[str]]:
        """DDS topic names of the readers and of the writers of the participants in ``foreign`` (ROS 2's), from
        discovery's samples as they come (reading every endpoint of the domain on every tick cost the watcher
        several % of a core beside 60 nodes)."""
        writers = self._discovery.followed_topics("writers")
        readers = self._discovery.followed_topics("readers")
        return ({topic for participant, topic in readers.values() if participant in foreign},
                {topic for participant, topic in writers.values() if participant in foreign})

    def _write_visible(self) -> None:
        text = "".join(f"{pid} {node}\n" for pid, node in sorted(self.visible.items()))
        tmp = f"{self.visible_path}.{os.getpid()}"
        try:
            with open(tmp, "w") as f:
                f.write(text)
            os.replace(tmp, self.visible_path)
        except OSError as exc:
            _log.warning("micros_rt: cannot write %s (%s): nodes of this host with ROS 2 peers stay off DDS; "
                         "MICROS_RT_ROS2=on makes them ROS 2 nodes without the host's gateway", self.visible_path, exc)

    def _keep_proxies(self, nodes: Mapping[int, NodeDescription]) -> None:
        want = {(pid, k): e for pid, d in nodes.items() for k, e in zip(d.keys(), d.endpoints)}
        changed = False
        for key in [k for k in self._proxies if k not in want]:
            entity, _guid = self._proxies.pop(key)
            from .participant import delete_entity

            delete_entity(entity)
            changed = True
        deadline = time.monotonic() + PROXY_BUDGET
        for key in sorted(set(want) - set(self._proxies)):
            if time.monotonic() > deadline:
                break  # the rest on the next ticks: the watcher looks for ROS 2 endpoints between them
            if key in self._unmade:
                continue
            made = self._make_proxy(want[key])
            if made is None:
                self._unmade.add(key)  # said once; made again when the node's description changes
            else:
                self._proxies[key] = made
                changed = True
        if changed or self._announced is None:
            self._announce(nodes)

    def _make_proxy(self, e: EndpointDescription) -> Optional[Tuple[Any, str]]:
        import_cyclonedds()
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from ...qos import AdvertiseQoSOptions, SubscribeQoSOptions, plain_reader_qos, reader_qos, writer_qos
        from .endpoints import make_user_data
        from .types import dds_topic_name, dds_type_for

        name = dds_topic_name(e.topic)
        try:
            dds_type = dds_type_for(_message_class(e))
            known = self._topics.get(name)
            if known is None:
                known = self._topics[name] = (Topic(self.dp, name, dds_type.idl_class), dds_type.type_name)
            elif known[1] != dds_type.type_name:
                raise ValueError(f"{name} is already {known[1]} on this host, not {dds_type.type_name}")
            user_data = make_user_data(**e.tag)
            if e.kind == "pub":
                options = AdvertiseQoSOptions.from_dict(e.options or {}, source=f"node description of {e.topic}")
                entity: Any = DataWriter(self._publisher, known[0], writer_qos(
                    options, queue_size=e.queue_size, latch=e.latch, user_data=user_data))
            else:
                depth = e.queue_size
                qos = (plain_reader_qos(queue_size=depth, user_data=user_data) if e.options is None else
                       reader_qos(SubscribeQoSOptions.from_dict(e.options, source=f"node description of {e.topic}"),
                                  queue_size=depth, user_data=user_data))
                entity = DataReader(self._subscriber, known[0], qos)
        except Exception as exc:  # a type, QoS or entity the gateway cannot build (DDSException too): said once
            if (e.topic, str(exc)) not in self._refused:
                self._refused.add((e.topic, str(exc)))
                _log.warning("micros_rt: ROS 2 tools will not see %s of this host's nodes (%s)", e.topic, exc)
            return None
        return entity, str(entity.guid)

    def _announce(self, nodes: Mapping[int, NodeDescription]) -> None:
        from .ros2_graph import NodeEntitiesInfo, ParticipantEntitiesInfo, split_node_name

        infos = []
        for pid, desc in sorted(nodes.items(), key=lambda kv: kv[1].node):
            guids = {e.kind: [] for e in desc.endpoints}  # type: Dict[str, List[str]]
            for k, e in zip(desc.keys(), desc.endpoints):
                made = self._proxies.get((pid, k))
                if made is not None:
                    guids.setdefault(e.kind, []).append(made[1])
            ns, name = split_node_name(desc.node)
            infos.append(NodeEntitiesInfo(node_namespace=ns, node_name=name,
                                          reader_gid_seq=[_gid(g) for g in sorted(guids.get("sub", []))],
                                          writer_gid_seq=[_gid(g) for g in sorted(guids.get("pub", []))]))
        sample = ParticipantEntitiesInfo(gid=_gid(self.guid), node_entities_info_seq=infos)
        try:
            self._info.write(sample)
            self._announced = sample
        except Exception as exc:  # the graph is a courtesy: the next change tries again
            _log.debug("micros_rt: announcing the host's nodes to ROS 2: %s", exc)

    def proxied(self) -> Dict[str, int]:
        """Node name -> its endpoints the gateway stands in for now (for tests and ``micros-rt doctor``)."""
        with self._lock:
            out: Dict[str, int] = {}
            for (pid, _e) in self._proxies:
                node = self._described[pid][1].node if pid in self._described else str(pid)
                out[node] = out.get(node, 0) + 1
            return out

    def close(self) -> None:
        """Delete the participant (its proxies and announcement go with it) and the built-in readers."""
        from .participant import delete_entity

        with self._lock:
            if self.closed:
                return
            self.closed = True
            self._discovery.close()
            self._proxies.clear()
            delete_entity(self.dp)
