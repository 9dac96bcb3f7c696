"""DDS topics outside the negotiation: a pushed reader of writers a program chooses by their tag, and the
writers other graphs' programs announce (the relay's import side, :mod:`micros_rt.bridges.relay`).

A topic's ordinary DDS reader delivers only samples of writers whose publisher accepted DDS with its node
(the negotiation), which is what keeps two ROS graphs on one domain apart. A relay between graphs needs
the opposite on purpose: samples of writers of *another* graph, chosen by their micros_rt tag
(``relay=<graph>``). :class:`DDSFeed` is that reader: Cyclone hands it samples on its receive thread, it
keeps those of accepted writers, decodes them and puts them into a :class:`~micros_rt.transports.base.PushReader`,
which never blocks that thread (a full queue drops its oldest, counted). The subscription it feeds
(``NodeHandle.subscribe_reader``) does the rest, as for any transport.

:class:`WriterDirectory` lists the writers the participant has discovered on a DDS topic with their tags
(:mod:`micros_rt.transports.dds.discovery`, the one reader of DDS discovery): how an importing relay learns the type of a topic it has
never seen (the exporter's tag names it).
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, NamedTuple, Optional

from ...cyclone import import_cyclonedds
import_cyclonedds()
from cyclonedds.core import DDSException, Listener
from cyclonedds.qos import Policy, Qos

from ..base import EndpointSpec, PushReader
from ...log import nonblocking_logger
from ...qos import SubscribeQoSOptions, describe_incompatible_policy, plain_reader_qos, reader_qos
from ...ratelimit import RateLimitedLog
from .backend import DDSBackend
from .discovery import Discovery
from .endpoints import DDSReader, make_user_data
from .types import dds_topic_name, dds_type_for

__all__ = ["DDSFeed", "DiscoveredWriter", "WriterDirectory"]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: ``accept(tag)``: keep samples of a writer with this micros_rt tag (None: a foreign writer, e.g. ROS 2)
Accept = Callable[[Optional[Dict[str, str]]], bool]


class DDSFeed:
    """Samples of one DDS topic from the writers ``accept`` keeps, into ``push`` (see the module's text)."""

    protocol = "DDS"

    def __init__(self, backend: DDSBackend, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                 push: PushReader, accept: Accept) -> None:
        self.topic = spec.topic
        self.dds_type = dds_type_for(spec.data_class)
        self.dds_topic = dds_topic_name(spec.topic)
        self._push = push
        self._accept = accept
        self.refused = 0      # samples of writers ``accept`` turned away
        self.unknown_writer = 0   # samples of a writer missing from the reader's matched writers (so no tag to judge)
        self.bad_input = 0    # samples that were not a valid encoding of the type
        self.lost = 0         # samples DDS reported lost: the writer's history dropped them before they arrived whole
        self._bad_log = RateLimitedLog(_log, interval=10.0)
        self._lock = threading.Lock()  # Cyclone may call the listener from more than one receive thread
        self._ros_type = str(spec.data_class._type)
        self._headers: Dict[str, Dict[str, str]] = {}   # writer guid -> the messages' _connection_header
        user_data = make_user_data(**spec.tag)
        # a latched topic too: several transient_local writers each send their history at once (static transforms)
        depth = spec.queue_size
        qos = (plain_reader_qos(queue_size=depth, transient_local=spec.latch, user_data=user_data) if options is None
               else reader_qos(options, queue_size=depth, transient_local=spec.latch, user_data=user_data))
        # not this process's own writers of the topic (an importing relay's local publication of the same name
        # would otherwise send every message to this reader too, only to be refused)
        qos += Qos(Policy.IgnoreLocal.Process)
        listener = Listener(on_data_available=self._on_data,  # type: ignore[no-untyped-call]
                            on_requested_incompatible_qos=self._on_incompatible, on_sample_lost=self._on_lost)
        self._reader = DDSReader(backend.participant, self.dds_topic, self.dds_type, qos, listener)
        self.guid = self._reader.guid
        self._backend = backend
        backend.announce(backend.participant, add_reader=self.guid)
        self._on_data(None)  # what arrived before the listener was attached (transient-local history)

    def _on_incompatible(self, _reader: Any, status: Any) -> None:
        self._bad_log.warning(("incompatible", int(status.last_policy_id)), "micros_rt: " + describe_incompatible_policy(
            int(status.last_policy_id), topic=self.topic, side="subscriber"))

    def _on_lost(self, _reader: Any, status: Any) -> None:
        self.lost = int(status.total_count)
        self._bad_log.warning("lost", f"micros_rt: DDS topic {self.dds_topic}: {self.lost} samples lost so far (the "
                              "writer's history dropped them before they arrived whole: a slow receiver, a full "
                              "socket buffer or a lossy link; a longer queue_size keeps more for resending)")

    def _on_data(self, _reader: Any) -> None:
        with self._lock:
            if self._reader.closed:
                return
            while True:
                try:
                    samples = self._reader.take_raw(64)
                except DDSException as exc:  # the reader is being deleted
                    _log.debug("micros_rt: DDS feed %s: %s", self.dds_topic, exc)
                    return
                if not samples:
                    return
                for payload, info in samples:
                    if not info.valid_data:
                        continue
                    writer = self._reader.writer_info(info.publication_handle)
                    if writer is None:
                        # Cyclone delivered it, yet does not list its writer among the reader's matches: not a writer
                        # turned away, so counted and said apart (a relay importing nothing would be silent otherwise)
                        self.unknown_writer += 1
                        self._bad_log.warning(
                            "unknown writer", f"micros_rt: DDS topic {self.dds_topic}: dropped a sample of writer "
                            f"handle {info.publication_handle:#x}, which the reader has no match data for (so no "
                            f"tag to judge); {self.unknown_writer} so far")
                        continue
                    if not self._accept(writer.tag):
                        self.refused += 1
                        continue
                    try:
                        msg = self.dds_type.decode(payload)
                    except ValueError as exc:
                        self.bad_input += 1
                        self._bad_log.warning(
                            writer.guid, f"micros_rt: DDS topic {self.dds_topic}: dropped a sample from writer "
                            f"{writer.guid} that is not a valid {self.dds_type.type_name} ({exc}); "
                            f"{self.bad_input} so far")
                        continue
                    header = self._headers.get(writer.guid)
                    if header is None:
                        # one dict per writer, as rospy shares one per connection: which writer sent it (a ROS 2
                        # writer has no node name; a micros_rt one's tag names it)
                        header = self._headers[writer.guid] = {
                            "callerid": (writer.tag or {}).get("node") or writer.guid, "writer": writer.guid,
                            "topic": self.topic, "type": self._ros_type, "transport": "DDS"}
                    msg._connection_header = header
                    self._push.put(msg, int(info.source_timestamp), writer.guid)

    def matched_writers(self) -> List[str]:
        return self._reader.matched_writer_guids()

    def close(self) -> None:
        self._push.close()
        with self._lock:
            if self._reader.closed:
                return
            self._backend.announce(self._backend.participant, remove=self.guid)
            self._reader.close()


class DiscoveredWriter(NamedTuple):
    guid: str
    participant: str
    tag: Dict[str, str]


class WriterDirectory:
    """The DDS writers this participant has discovered, with their micros_rt tags, and on demand whether a reader
    is alive (:class:`~micros_rt.transports.dds.discovery.Discovery`, which :attr:`discovery` is, for the rest)."""

    def __init__(self, backend: DDSBackend) -> None:
        self.discovery = Discovery(backend.participant.dp, kinds=("writers",))
        self._lock = threading.Lock()
        self._readers: FrozenSet[str] = frozenset()
        self._readers_at = -1.0

    def writers(self, dds_topic: str) -> List[DiscoveredWriter]:
        """The micros_rt writers of ``dds_topic`` known now (foreign writers have no tag and are left out)."""
        out: List[DiscoveredWriter] = []
        for endpoint in self.discovery.writers(dds_topic):
            tag = endpoint.tag
            if tag is not None:
                out.append(DiscoveredWriter(endpoint.guid, endpoint.participant, tag))
        return out

    def tags(self, dds_topic: str) -> List[Dict[str, str]]:
        """Tags of the micros_rt writers of ``dds_topic`` known now."""
        return [w.tag for w in self.writers(dds_topic)]

    def reader_alive(self, guid: str) -> bool:
        """Whether the reader ``guid`` is in discovery now (looked up at most every 0.2 s)."""
        now = time.monotonic()
        with self._lock:
            if now - self._readers_at > 0.2:
                self._readers = frozenset(e.guid for e in self.discovery.readers())
                self._readers_at = now
            return guid in self._readers
