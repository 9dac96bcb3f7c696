"""The DDS side of a subscription: its offer (the reader's GUID, or a lazy offer with ROS 2 visibility off),
the readers it opens (the topic's, a latched one, another graph's relay topic it follows) and the writers a
publisher's answer names, accepted into the subscription's exactly-once table (:mod:`.exactly_once`).

The readers feed the subscription's delivery thread, which takes their samples (a pulled reader), holds or
drops them per writer and decodes what it delivers. Importing this module imports no DDS library."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional, Protocol, Tuple

from ...exceptions import MicrosRtError
from ...log import nonblocking_logger
from ...negotiation import DDS, DDSAnswer, DDSOffer
from ..base import EndpointSpec
from ..negotiated import SubscriptionHost, SubscriptionSide
from ..links import PseudoLink, add_link
from .exactly_once import Accepted, WriterTable

if TYPE_CHECKING:
    from .backend import DDSBackend, DDSTopicReader

__all__ = ["DDSSubscription", "DDSSubscriptionHost"]

_log = nonblocking_logger("rosout.micros_rt")


class DDSSubscriptionHost(SubscriptionHost, Protocol):
    """What the DDS side needs beyond every side's host: the exactly-once table and a place for its readers."""

    writers: WriterTable

    def add_reader(self, reader: "DDSTopicReader", *, duplicate: bool) -> None:
        """Let the delivery thread take ``reader``'s samples; ``duplicate``: it may see samples another reader
        of the subscription sees too (a latched reader beside the topic's)."""

    def reader_wakes(self) -> bool:
        """True when a reader must wake the delivery thread per sample (it waits on no Cyclone wait set)."""

    def matches_changed(self) -> None:
        """A writer matched or went (Cyclone's thread)."""

    def incompatible(self, policy: int) -> None:
        """A writer's QoS cannot match the reader's (Cyclone's thread)."""


class DDSSubscription(SubscriptionSide):
    """A subscription's DDS readers and accepted writers (see the module's text)."""

    protocol = DDS
    words = "DDS"

    def __init__(self, host: DDSSubscriptionHost, *, backend: "Optional[DDSBackend]",
                 lazy: "Optional[Callable[[], Optional[DDSBackend]]]" = None) -> None:
        super().__init__(host)
        self.dds_host = host
        self.backend = backend
        #: with ROS 2 visibility off: opens the process's DDS back end when a first publisher would take DDS
        self._lazy = lazy
        self._opening = threading.Lock()
        self.reader: "Optional[DDSTopicReader]" = None
        self.tl_reader: "Optional[DDSTopicReader]" = None
        self._followed: Dict[Tuple[str, bool], "DDSTopicReader"] = {}  # (topic, latched) -> reader (_follow)
        if backend is not None:
            try:
                self.reader = self._open_reader(latched=False)
            except MicrosRtError as exc:
                _log.warning("micros_rt: topic %s will use TCPROS only: %s", host.topic, exc)

    def _open_reader(self, *, latched: bool, topic: Optional[str] = None) -> "DDSTopicReader":
        """A DDS reader of the subscription's topic (or of ``topic``, another name of its data) feeding the
        delivery thread."""
        assert self.backend is not None
        host = self.dds_host
        spec = EndpointSpec(topic or host.topic, host.data_class, host.queue_size, latched, host.tag)
        reader = self.backend.open_reader(spec, host.options, host.matches_changed, host.incompatible,
                                          wake_on_data=host.reader_wakes())
        host.add_reader(reader, duplicate=latched and topic is None)
        return reader

    # -- negotiation (rospy's connect threads) ----------------------------
    def offer(self, held: str) -> Optional[List[Any]]:
        host, reader, dds = self.dds_host, self.reader, self.backend
        if reader is None and self._lazy is not None:
            from .participant import domain_id_from_env

            return DDSOffer(domain=domain_id_from_env(), topic="", type_name="", md5=host.data_class._md5sum,
                            qos=host.effective, reader="", participant="", graph=host.writers.graph,
                            lazy=True).to_xmlrpc()
        if reader is not None and dds is not None:
            return DDSOffer(domain=dds.domain_id, topic=reader.dds_topic, type_name=reader.dds_type.type_name,
                            md5=host.data_class._md5sum, qos=host.effective, reader=reader.guid,
                            participant=dds.participant.guid, graph=host.writers.graph, follow=True).to_xmlrpc()
        return None

    def read_answer(self, params: Any, source: str) -> DDSAnswer:
        return DDSAnswer.from_xmlrpc(params, source=source)

    def peer_of(self, answer: Any) -> str:
        return str(answer.writer)

    def open_first(self) -> bool:
        """With ROS 2 visibility off: open the DDS reader now (a publisher would take DDS; rospy's connect
        thread). True when there is one."""
        with self._opening:
            if self.reader is None and self._lazy is not None and not self.host.closed:
                backend = self._lazy()
                self._lazy = None
                if backend is not None:
                    self.backend = backend
                    try:
                        self.reader = self._open_reader(latched=False)
                        _log.info("micros_rt: topic %s: DDS reader made",
                                  self.host.topic)
                    except MicrosRtError as exc:
                        _log.warning("micros_rt: topic %s will use TCPROS only: %s", self.host.topic, exc)
        return self.reader is not None

    def connect(self, pub_uri: str, answer: Any) -> Tuple[int, str, int]:
        host = self.dds_host
        if host.closed:
            return 0, "subscriber closed", 0
        if answer.latch:
            with host.lock:  # two latched publishers connecting at once must not make two readers
                if self.tl_reader is None and self.backend is not None:
                    try:
                        self.tl_reader = self._open_reader(latched=True)
                    except MicrosRtError as exc:
                        _log.warning("micros_rt: topic %s: no latched message over DDS: %s", host.topic, exc)
        dds_topic = self.reader.dds_topic if self.reader else host.topic
        if answer.via and answer.topic and answer.topic != host.topic:
            # the relay's writers write the topic under its outside name: read it there too
            dds_topic = self._follow(answer.topic, answer.latch)
            if not dds_topic:
                return 0, f"cannot read {answer.topic} over DDS", 0
        source = (f"straight from the writers of graph {answer.via}'s relay (now {answer.writer}), no hop through "
                  f"{answer.node or pub_uri}") if answer.via else f"from writer {answer.writer}"
        conn = PseudoLink(host.topic, pub_uri, "i", f"DDS connection on topic {dds_topic} {source}",
                                    peer_guid=answer.writer, on_close=host.writers.connection_closed,
                                    callerid_pub=answer.node)
        accepted = Accepted(pub_uri, answer.node, answer.latch, conn)
        host.writers.accept(answer.writer, accepted, answer.qos)
        if answer.via:
            host.writers.delegate(answer.via, accepted, answer.qos)
        host.raise_priority(answer.qos)
        if not add_link(host.topic, conn, publisher=False):
            conn.close()
            return 0, "subscriber closed", 0
        _log.debug("micros_rt: topic %s: receiving from %s over DDS", host.topic, pub_uri)
        host.wake()
        return 1, f"Connected topic[{host.topic}] over DDS", 0

    def _follow(self, topic: str, latched: bool) -> str:
        """A reader of ``topic`` (another ROS name of this subscription's data, a relay's outside name) for
        delegated writers that write there; opened once, closed with the subscription. Its DDS topic name,
        or "" when DDS refuses it (the publisher then serves this subscriber over TCPROS)."""
        host = self.host
        with host.lock:
            reader = self._followed.get((topic, latched))
            if reader is None and self.backend is not None and not host.closed:
                try:
                    reader = self._open_reader(latched=latched, topic=topic)
                except MicrosRtError as exc:
                    _log.warning("micros_rt: topic %s: cannot read %s over DDS: %s", host.topic, topic, exc)
                    return ""
                self._followed[(topic, latched)] = reader
        return reader.dds_topic if reader is not None else ""

    def close(self) -> None:
        """The readers are closed by the subscription (the delivery thread takes from them until it stops)."""
        self.reader = self.tl_reader = None
