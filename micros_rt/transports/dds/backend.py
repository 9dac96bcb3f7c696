"""DDS as a micros_rt back end (:class:`micros_rt.transports.base.Backend`): Cyclone writers and readers on the
process participant, the ROS 2 graph announcement, and DDS errors translated at this boundary."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple, TypeVar

from ...cyclone import import_cyclonedds
import_cyclonedds()
from cyclonedds.core import DDSException, Listener

from ..base import SOURCE_ORDER, TIME_FILTER, EndpointSpec, RemoteWriter, Sample, send_with_backoff
from ...exceptions import MicrosRtError, PublishTimeoutError, TransportError
from ...qos import (
    PUBLISH_BLOCK_TIMEOUT,
    RELIABLE_MAX_BLOCKING_TIME,
    AdvertiseQoSOptions,
    SubscribeQoSOptions,
    TransportPriority,
    is_lossless,
    plain_reader_qos,
    priority_socket_priority,
    priority_tos,
    reader_qos,
    writer_qos,
)
from .congestion import RELEASED_WRITE_MIN
from .endpoints import DDSReader, DDSWriter, make_user_data, wait_for_acks
from .participant import DDSParticipant, priority_participant, priority_participants
from .types import DDSType, dds_topic_name, dds_type_for
from ...log import nonblocking_logger

__all__ = ["DDSBackend", "DDSTopicWriter", "DDSTopicReader"]

_log = nonblocking_logger("rosout.micros_rt.dds")

_DDS_RETCODE_TIMEOUT = -10

#: A writer with no room waits for acknowledgements in slices of at least this long (s): Cyclone wakes the
#: wait at the acknowledgement, so a long slice costs nothing and spares the retries of a short one.
WAIT_FOR_ROOM_MIN = 0.05


class DDSTopicWriter:
    """A publication's DDS writer: ``prepare`` encodes CDR, ``send`` writes it (blocking when lossless)."""

    protocol = "DDS"

    def __init__(self, backend: "DDSBackend", spec: EndpointSpec, options: AdvertiseQoSOptions) -> None:
        self._backend = backend
        self.topic = spec.topic
        self.dds_type: DDSType = dds_type_for(spec.data_class)
        self.dds_topic = dds_topic_name(spec.topic)
        self.lossless = is_lossless(spec.queue_size) and not options.using_best_effort_protocol
        qos = writer_qos(options, queue_size=spec.queue_size, latch=spec.latch, user_data=make_user_data(**spec.tag))
        #: the participant whose sockets carry this writer's transport priority (:meth:`DDSBackend.participant_for`)
        self.participant = backend.participant_for(options.transport_priority)
        self._writer = DDSWriter(self.participant, self.dds_topic, self.dds_type, qos,
                                 latency_budget=options.latency_budget)
        self._ref = self._writer._ref
        self._write = self._writer.write_serialized
        self._congestion = self.participant.congestion
        self.guid = self._writer.guid
        self._encode = self.dds_type.encode  # raises genpy.SerializationError on a bad field value
        self._latch = spec.latch
        self._closed = False
        backend.announce(self.participant, add_writer=self.guid)

    @property
    def matched_count(self) -> int:
        return self._writer.matched_count

    def prepare(self, msg: Any) -> Optional[bytes]:
        """CDR of ``msg``, or None while no matched reader wants it (a latched topic always encodes: Cyclone
        keeps the last sample for late joiners)."""
        writer = self._writer
        if (writer._matched and writer.wanted) or self._latch:
            return self._encode(msg)
        return None

    def want(self, wanted: bool, generation: Optional[int] = None) -> None:
        """Whether the matched readers want the samples (the publication decides from :meth:`matched_readers`:
        micros_rt readers of its graph that it serves over shared memory or TCPROS drop them unread). Writing is
        switched off only when no match changed since ``generation`` (:meth:`match_generation`) was read."""
        writer = self._writer
        if wanted or generation is None or generation == writer.match_generation:
            writer.wanted = wanted

    def match_generation(self) -> int:
        return self._writer.match_generation

    def matched_readers(self) -> Dict[str, Optional[Dict[str, str]]]:
        """Matched readers: GUID -> micros_rt tag (None: a foreign reader, e.g. ROS 2)."""
        return self._writer.matched_readers()

    def try_send(self, prepared: bytes) -> bool:
        """Write at once, or return False when Cyclone has no room (more unacknowledged data than the
        writer's window): the writer's max_blocking_time is 0, so Cyclone never waits holding the GIL."""
        ret = self._write(prepared)
        if ret >= 0:
            return True
        if ret == _DDS_RETCODE_TIMEOUT:
            return False
        if self._closed:
            raise TransportError(f"topic {self.topic}: this DDS writer is closed (its publication was unregistered); "
                                 f"nothing was sent")
        raise TransportError(f"topic {self.topic}: DDS write failed (Cyclone return code {ret})")

    def wait_for_room(self, timeout: float) -> None:
        """Wait (GIL released) until the readers acknowledged what was sent, at most ``timeout`` s."""
        wait_for_acks(self._ref, max(timeout, WAIT_FOR_ROOM_MIN))

    def may_wait(self, prepared: bytes) -> bool:
        """A large sample while the network is what limits this writer (its last large write waited for
        socket room behind a slow link), or any sample while its participant's transmit socket is congested
        (another topic of the same transport priority just waited: :mod:`~micros_rt.transports.dds.congestion`):
        a small sample's ``sendmsg`` would wait behind those fragments. On loopback a 900 KB write takes
        ~0.5 ms and stays on the caller's thread, with no hop to the send queue's."""
        congestion = self._congestion
        return (len(prepared) >= RELEASED_WRITE_MIN and congestion.network_bound(self._ref)) or congestion.active()

    def send(self, prepared: bytes) -> None:
        """Write, waiting (in Python, other threads running) while a reliable subscriber is behind; raise
        :class:`PublishTimeoutError` after the bound."""
        bound = PUBLISH_BLOCK_TIMEOUT if self.lossless else RELIABLE_MAX_BLOCKING_TIME
        if not send_with_backoff(self.try_send, prepared, bound, lambda: self._closed, self.wait_for_room):
            raise PublishTimeoutError(
                f"topic {self.topic}: publish() stayed blocked for {bound:.1f} s because a reliable DDS "
                f"subscriber does not keep up{' (queue_size=None never drops)' if self.lossless else ''}. "
                f"The subscribers: {', '.join(sorted(self.matched_peers())) or 'none matched'}")

    def matched_peers(self) -> Set[str]:
        return set(self._writer.matched_reader_guids())

    def close(self) -> None:
        self._closed = True
        self._backend.announce(self.participant, remove=self.guid)
        self._writer.close()


class DDSTopicReader:
    """A subscription's DDS reader; its ``condition`` wakes the delivery thread's wait set."""

    protocol = "DDS"
    #: Cyclone applies TimeBasedFilter in the reader (and Lifespan in its cache)
    enforces = frozenset({TIME_FILTER, SOURCE_ORDER})  # Cyclone's TimeBasedFilter and DestinationOrder

    def __init__(self, backend: "DDSBackend", spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                 wake: Callable[[], None], on_incompatible: Callable[[int], None], *,
                 wake_on_data: bool = False) -> None:
        self.dds_type = dds_type_for(spec.data_class)
        self.dds_topic = dds_topic_name(spec.topic)
        user_data = make_user_data(**spec.tag)
        depth = 1 if spec.latch else spec.queue_size
        if options is None:
            qos = plain_reader_qos(queue_size=depth, transient_local=spec.latch, user_data=user_data)
        else:
            qos = reader_qos(options, queue_size=depth, transient_local=spec.latch, user_data=user_data)
        callbacks: Dict[str, Callable[..., None]] = {}
        if wake_on_data:  # for a waiter with no Cyclone wait set to attach ``condition`` to (Cyclone's thread)
            callbacks["on_data_available"] = lambda _r: wake()
        listener = Listener(  # type: ignore[no-untyped-call]
            on_requested_incompatible_qos=lambda _r, status: on_incompatible(int(status.last_policy_id)),
            on_subscription_matched=lambda *_: wake(), **callbacks)
        self._reader = DDSReader(backend.participant, self.dds_topic, self.dds_type, qos, listener)
        self._backend = backend
        self.condition = self._reader.condition
        self.guid = self._reader.guid
        backend.announce(backend.participant, add_reader=self.guid)
        self.take: Callable[[int], Sequence[Sample]] = self._reader.take_raw
        self.decode: Callable[[bytes], Any] = self.dds_type.decode

    def writer(self, handle: Any) -> Optional[RemoteWriter]:
        info = self._reader.writer_info(handle)
        return None if info is None else RemoteWriter(info.guid, info.tag)

    def matched_writers(self) -> Set[str]:
        return set(self._reader.matched_writer_guids())

    def close(self) -> None:
        self._backend.announce(self._backend.participant, remove=self.guid)
        self._reader.close()


class DDSBackend:
    """The process's DDS back end: its participant with the readers and the writers of one transport priority,
    and a participant per other priority of its writers (:meth:`participant_for`)."""

    protocol = "DDS"

    def __init__(self, participant: DDSParticipant, node_name: str) -> None:
        self.participant = participant
        self.node_name = node_name
        self._announcements: Dict[str, _Announcement] = {}  # participant GUID -> its ROS 2 graph announcement
        self._lock = threading.Lock()
        #: the UDP send buffer of participants whose writers are all below HIGH, when the node's profile names a
        #: link of limited bandwidth (:func:`~micros_rt.qos.links.send_buffer_for` of the slowest); None: Cyclone's
        self.send_buffer_below_high: Optional[int] = None

    @property
    def domain_id(self) -> int:
        return self.participant.domain_id

    def participant_for(self, priority: TransportPriority) -> DDSParticipant:
        """The participant a writer of transport ``priority`` writes through: the process participant when its
        sockets carry that priority (the first writer's marks them), else the priority's own participant,
        whose sockets carry it (:func:`~micros_rt.transports.dds.participant.priority_participant`). So each
        DDS topic leaves with its own priority's DSCP, and a LOW camera's fragments never fill the socket a
        HIGH topic is sent through. When a priority participant cannot start, the process participant carries
        every priority, marked with the highest (said once in the log).

        With :attr:`send_buffer_below_high` (the node's profile names a slow link), a participant for writers
        below HIGH gets that small send buffer: they keep little queued in the link, and a FIFO link (one that
        does not honour DSCP) serves HIGH topics after milliseconds, not after its whole queue."""
        level, tos, so_priority = int(priority), priority_tos(priority), priority_socket_priority(priority)
        main = self.participant
        if main.claim_priority(level, tos, so_priority):
            chosen: Optional[DDSParticipant] = main
        else:
            chosen = priority_participant(main.domain_id, level, tos, so_priority)
        if chosen is None:
            main.mark_priority(level, tos, so_priority)
            return main
        if self.send_buffer_below_high is not None and level < TransportPriority.HIGH:
            chosen.limit_send_buffer(self.send_buffer_below_high)
        return chosen

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> DDSTopicWriter:
        return _translated(lambda: DDSTopicWriter(self, spec, options), spec.topic, "writer")

    def open_reader(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions], wake: Callable[[], None],
                    on_incompatible: Callable[[int], None], *, wake_on_data: bool = False) -> DDSTopicReader:
        return _translated(lambda: DDSTopicReader(self, spec, options, wake, on_incompatible,
                                                  wake_on_data=wake_on_data), spec.topic, "reader")

    def describe(self) -> List[str]:
        lines = [f"DDS domain {self.participant.domain_id}, participant {self.participant.guid}"]
        lines += [f"DDS domain {p.domain_id}, participant {p.guid} (writers of transport priority "
                  f"{TransportPriority(p.priority).name})" for p in priority_participants()
                  if p.priority is not None and p.domain_id == self.participant.domain_id]
        return lines

    def close(self, timeout: float = 2.0) -> None:
        """Before the participants close: let announcers still starting finish creating their entities (a
        participant deleted while another thread creates a Topic on it is a race inside Cyclone)."""
        with self._lock:
            announcements = list(self._announcements.values())
        deadline = time.monotonic() + timeout
        for announcement in announcements:
            announcement.wait_started(max(0.0, deadline - time.monotonic()))

    def announce(self, participant: DDSParticipant, *, add_reader: str = "", add_writer: str = "",
                 remove: str = "") -> None:
        """Keep ROS 2's graph (``ros_discovery_info``) told which endpoints this node has on ``participant``
        (ROS 2 names a node per participant: a priority participant announces its writers itself)."""
        with self._lock:
            announcement = self._announcements.get(participant.guid)
            if announcement is None:
                announcement = self._announcements[participant.guid] = _Announcement(participant, self.node_name)
        announcement.update(add_reader, add_writer, remove)


class _Announcement:
    """One participant's ``ros_discovery_info``: a courtesy to ROS 2 tools, kept off the caller's path. The
    announcer (its Topic costs ~25 ms of Cyclone type-object building) starts on a background thread with
    the first endpoint, and updates queue up until it runs. A failure is logged once as a warning and
    changes nothing else."""

    def __init__(self, participant: DDSParticipant, node_name: str) -> None:
        self.participant = participant
        self.node_name = node_name
        self._announcer: Any = None  # None: not started, True: starting, False: failed
        self._pending: List[Tuple[str, str, str]] = []
        self._lock = threading.Lock()
        self._thread: Optional[threading.Thread] = None

    def wait_started(self, timeout: float) -> None:
        """Wait, at most ``timeout`` s, until the announcer's start (Cyclone entities on the participant) ended."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)

    def update(self, add_reader: str, add_writer: str, remove: str) -> None:
        with self._lock:
            self._pending.append((add_reader, add_writer, remove))
            if self._announcer is None:
                self._announcer = True  # starting
                self._thread = threading.Thread(target=self._start, name="micros_rt ROS 2 graph", daemon=True)
                self._thread.start()
                return
            if self._announcer is True or self._announcer is False:
                return
            announcer, pending, self._pending = self._announcer, self._pending, []
        for r, w, gone in pending:
            announcer.update(add_reader=r, add_writer=w, remove=gone)

    def _start(self) -> None:
        from .ros2_graph import Ros2GraphAnnouncer

        announcer: Any = False
        for attempt in range(3):
            try:
                announcer = Ros2GraphAnnouncer(self.participant, self.node_name)
                break
            except (MicrosRtError, DDSException) as exc:
                # seen once in 84 processes of a 30-node graph start: Cyclone refused the Topic
                # (BAD_PARAMETER) while the main thread created its own topics; a second try succeeds
                if attempt == 2:
                    _log.warning("micros_rt: ROS 2 tools will not name this node (ros_discovery_info: %s)", exc)
                else:
                    time.sleep(0.2)
        with self._lock:
            self._announcer = announcer
            pending, self._pending = self._pending, []
        if announcer:
            for r, w, gone in pending:
                announcer.update(add_reader=r, add_writer=w, remove=gone)


T = TypeVar("T")


def _translated(make: Callable[[], T], topic: str, what: str) -> T:
    try:
        return make()
    except MicrosRtError:
        raise
    except DDSException as exc:
        raise TransportError(f"topic {topic}: cannot create the DDS {what}: {exc}") from exc
