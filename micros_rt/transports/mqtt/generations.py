"""Which mqtt_client generation to write on each MQTT topic, read from what the peers put on the broker.

mqtt_client's two ROS 1 generations cannot read each other's data: 1.x (1.0-1.1) reads the first payload
byte as a flag and aborts ("Duration is out of dual 32-bit range") when a 2.x payload's first byte is not 0;
2.x (2.0-2.3) cannot deserialize a 1.x type announcement and never subscribes the data topic. A reader
announces nothing, but an mqtt_client peer writes its own topics' type announcements, retained, on
``mqtt_client/ros_msg_type/<topic>`` (with every message), and those say the generation: three strings for
1.x, a fourth one-byte ``stamped`` field for 2.x. So a writer subscribes ``mqtt_client/ros_msg_type/#``
and writes each of its topics in the generation of the peers it finds there:

1. a fixed setting: the topic's own ``mqtt_client_version``, else the bridge's (``bridge/mqtt_client_version``,
   the back end's ``mqtt_client_version``);
2. else the generation of the peers' announcements (topics this client does not write itself): when they
   all agree, theirs; when both generations are on the broker, that of the announced topics sharing the
   most leading topic levels with the topic written (``robot1/odom`` for ``robot1/cmd``); when those still
   disagree, 1.x (a 2.x reader of a 1.x topic logs an error and gets nothing; a 1.x reader of a 2.x payload
   aborts), with a warning naming the topics;
3. else (no peer announcement seen) 2.x.

A decision that changes (a peer appears, or changes generation) is re-announced at once in the new form.
An announcement this client published itself is recognised by its bytes and ignored, so a retained
announcement of an earlier run of the same topic does not decide its own generation.
"""

from __future__ import annotations

import threading
from typing import Dict, Iterable, List, Optional, Set, Tuple

from .codec import ROS_MSG_TYPE_PREFIX, CodecError, WireGeneration, decode_msg_type

__all__ = ["ANNOUNCEMENTS", "Decision", "PeerGenerations"]

#: The subscription that shows every type announcement on the broker (retained ones at once).
ANNOUNCEMENTS = ROS_MSG_TYPE_PREFIX + "#"

#: (generation, why in words)
Decision = Tuple[WireGeneration, str]


def _common_levels(a: str, b: str) -> int:
    n = 0
    for x, y in zip(a.split("/"), b.split("/")):
        if x != y:
            break
        n += 1
    return n


class PeerGenerations:
    """The peers' generations as announced on the broker, and the decision for each topic written.

    ``fixed``: the bridge-wide setting (None: follow the peers); ``fixed_topics``: per-topic settings;
    ``written``: the MQTT topics this client writes (their announcements are this client's, not a peer's)."""

    def __init__(self, *, fixed: Optional[WireGeneration] = None, default: WireGeneration = WireGeneration.V2,
                 fixed_topics: Optional[Dict[str, WireGeneration]] = None, written: Iterable[str] = ()) -> None:
        self.fixed = fixed
        self.default = default
        self.fixed_topics = dict(fixed_topics or {})
        self._lock = threading.Lock()
        self._written: Set[str] = set(written)
        self._ours: Dict[str, bytes] = {}                 # topic -> the announcement this client last published
        self._peers: Dict[str, WireGeneration] = {}       # announced topic -> its generation (peers only)
        self._last: Dict[str, bytes] = {}                 # announced topic -> the last announcement seen

    @property
    def follows_peers(self) -> bool:
        """True when some topic's generation is read from the broker (no setting fixes every topic)."""
        return self.fixed is None

    def knows(self, topic: str) -> bool:
        """True when ``topic``'s generation is set or a peer on the broker has announced one (else the bridge
        does not know whom it writes for)."""
        if topic in self.fixed_topics or self.fixed is not None:
            return True
        with self._lock:
            return bool(self._peers)

    def published(self, topic: str, announcement: bytes) -> None:
        """This client published ``announcement`` on ``topic``'s type topic (its echo is not a peer's)."""
        with self._lock:
            self._ours[topic] = bytes(announcement)
            self._last.pop(topic, None)

    def observe(self, type_topic: str, payload: bytes) -> bool:
        """An announcement seen on the broker; True when it changed what the peers are known to speak."""
        if not type_topic.startswith(ROS_MSG_TYPE_PREFIX):
            return False
        topic = type_topic[len(ROS_MSG_TYPE_PREFIX):]
        with self._lock:
            if self._last.get(topic) == payload:
                return False            # mqtt_client repeats its announcement with every message
            self._last[topic] = payload
            if topic in self._written or self._ours.get(topic) == bytes(payload):
                return False
            if not payload:                                  # a retained announcement cleared
                return self._peers.pop(topic, None) is not None
            try:
                wire = decode_msg_type(payload).wire
            except CodecError:
                return False                                 # the topic's reader reports it; it says nothing here
            before = self._peers.get(topic)
            self._peers[topic] = wire
            return before is not wire

    def peers(self) -> Dict[str, WireGeneration]:
        """Announced topics of peers and their generations."""
        with self._lock:
            return dict(self._peers)

    def decide(self, topic: str) -> Decision:
        """The generation to write on ``topic`` and why (see the module docstring)."""
        if topic in self.fixed_topics:
            wire = self.fixed_topics[topic]
            return wire, f"set for this topic (mqtt_client_version: {int(wire)})"
        if self.fixed is not None:
            return self.fixed, f"set (mqtt_client_version: {int(self.fixed)})"
        with self._lock:
            peers = dict(self._peers)
        if not peers:
            return self.default, "no mqtt_client peer announced a type on the broker"
        kinds = set(peers.values())
        if len(kinds) == 1:
            wire = kinds.pop()
            return wire, f"the peers announce in {wire.label} ({_names(peers)})"
        best = max(_common_levels(topic, t) for t in peers)
        nearest = {t: w for t, w in peers.items() if _common_levels(topic, t) == best}
        near_kinds = set(nearest.values())
        if best > 0 and len(near_kinds) == 1:
            wire = near_kinds.pop()
            return wire, (f"both generations are on the broker; the nearest announced topics ({_names(nearest)}) "
                          f"are {wire.label}")
        return WireGeneration.V1, (f"both generations are on the broker ({_names(peers)}) and none is nearer "
                                   "to this topic: 1.x, which no peer aborts on (a 2.x peer cannot read it; set "
                                   "mqtt_client_version on this topic)")


def _names(peers: Dict[str, WireGeneration], limit: int = 4) -> str:
    items: List[str] = [f"'{t}' {w.label}" for t, w in sorted(peers.items())]
    return ", ".join(items[:limit]) + (f", and {len(items) - limit} more" if len(items) > limit else "")
