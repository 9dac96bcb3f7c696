"""The bridge node: ROS topics and services on one side, the microcontroller link on the other.

The ROS side uses micros_rt's public API, so micros_rt nodes hear the board's streams over DDS and stock
nodes over TCPROS, as negotiated; services use rospy's own ``Service``/``ServiceProxy`` (``rosservice``
works). One delivery thread publishes what the board sends and watches its deadlines; callbacks of
subscribed topics run on micros_rt's delivery threads, never on the link's socket threads.

>>> micros_rt.init_node("mcu_bridge")                                  # doctest: +SKIP
>>> with McuBridge(load_config("mcu.yaml"), deadline_cb=print):        # doctest: +SKIP
...     micros_rt.spin()
"""

from __future__ import annotations

import functools
import json
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional

import rospy
from std_msgs.msg import String

import micros_rt
from micros_rt.log import nonblocking_logger
from micros_rt.qos.enforcement import DeadlineMissed, DeadlineMonitor, TimeFilter
from micros_rt.qos.options import SubscribeQoSOptions

from ...transports.mcu import wire
from ...transports.mcu.config import McuConfig, ServiceEntry, TopicEntry
from ...transports.mcu.errors import McuServiceError, WireError
from ...transports.mcu.link import LinkStats, McuLink, UdpReader, UdpWriter

__all__ = ["McuBridge", "StatsCallback"]

_log = nonblocking_logger("rosout.micros_rt.mcu")

#: Called with every counters snapshot (the ``~stats`` content as a dict).
StatsCallback = Callable[[Dict[str, Any]], None]

_PUBLISH_QUEUE = 100   # ROS-side publisher of a board stream: keeps the newest 100, never blocks the bridge
_SUBSCRIBE_QUEUE = 10  # ROS-side subscriber of a topic for the board
_POLL = 0.05           # seconds between deadline checks
_DEADLINE_REMINDER = 10.0  # seconds between log lines while a stream stays silent
_MAX_OUTSTANDING = 8   # board -> ROS calls whose ROS service has not answered yet


@dataclass
class _FromStream:
    entry: TopicEntry
    reader: UdpReader
    publisher: micros_rt.Publisher
    time_filter: TimeFilter
    deadline: DeadlineMonitor
    in_silence: bool = False
    last_reminder: float = 0.0


class McuBridge:
    """Runs one microcontroller link inside the current node (call :func:`micros_rt.init_node` first).

    - ``deadline_cb``: called (on the bridge's delivery thread) with a :class:`DeadlineMissed` when a
      ``from_microcontroller`` stream with a ``deadline`` goes silent, once per deadline of silence.
    - ``stats_cb``: called with the counters every ``stats_period`` seconds (also published, as JSON in a
      ``std_msgs/String``, on ``~stats``).

    Raises :class:`micros_rt.TransportError` when a socket cannot be bound. ``close()`` (or leaving the
    ``with`` block) stops everything; it is harmless twice.
    """

    def __init__(self, config: McuConfig, *, deadline_cb: Optional[Callable[[DeadlineMissed], None]] = None,
                 stats_cb: Optional[StatsCallback] = None) -> None:
        self.config = config
        self.stats = LinkStats()
        self._deadline_cb = deadline_cb
        self._stats_cb = stats_cb
        self._closed = threading.Event()
        self._wake = threading.Event()
        self._subscribers: List[micros_rt.Subscriber] = []
        self._services: List[rospy.Service] = []
        self._outstanding = 0
        self._outstanding_lock = threading.Lock()
        self.link = McuLink(config, stats=self.stats)
        try:
            self._open()
        except BaseException:
            self.close()
            raise
        self._thread = threading.Thread(target=self._deliver_loop, name="mcu-bridge delivery", daemon=True)
        self._thread.start()

    def _open(self) -> None:
        nh = micros_rt.NodeHandle()
        now = time.monotonic()
        self._streams = []
        for entry in self.config.from_microcontroller:
            publisher = nh.advertise_with_qos(entry.topic, entry.data_class, _PUBLISH_QUEUE, entry.advertise)
            reader = self.link.open_reader(entry, self._wake.set)
            self._streams.append(_FromStream(entry, reader, publisher,
                                             TimeFilter(entry.subscribe.time_filter_duration),
                                             DeadlineMonitor(entry.subscribe.deadline, start=now)))
        # Any publisher on the ROS side is welcome (best effort or reliable, stamped or not): the link is
        # the narrow part, and it applies the entry's QoS itself (UdpWriter.offer).
        ros_side = SubscribeQoSOptions(using_best_effort_protocol=True, ordered_by_sending_timestamp=False)
        self._writers: List[UdpWriter] = []
        for entry in self.config.to_microcontroller:
            writer = self.link.open_writer(entry)
            self._writers.append(writer)
            self._subscribers.append(nh.subscribe_with_qos(entry.topic, entry.data_class, _offer_callback(writer),
                                                           _SUBSCRIBE_QUEUE, ros_side))
        for service in self.config.services_on_microcontroller:
            self.stats.declare("services_on_microcontroller", service.name, ("calls", "ok", "failed", "timeout"))
            self._services.append(rospy.Service(service.service, service.service_class,
                                                functools.partial(self._call_board, service)))
        if self.config.services_for_microcontroller:
            for service in self.config.services_for_microcontroller:
                self.stats.declare("services_for_microcontroller", service.name, ("calls", "ok", "failed"))
            self.link.serve_calls(self._call_ros)
        self._stats_pub = nh.advertise("~stats", String, 1, latch=True)
        self.stats_topic: str = self._stats_pub.resolved_name
        board, bind = self.config.microcontroller, self.config.bind
        _log.info("micros_rt: mcu-bridge: board %s (topics %d, services %d), bridge %s (topics %d, services %d); "
                  "%d streams from the board, %d topics to it, %d + %d services; counters on %s",
                  board.address, board.topic_port, board.service_port, bind.address, bind.topic_port,
                  bind.service_port, len(self.config.from_microcontroller), len(self.config.to_microcontroller),
                  len(self.config.services_on_microcontroller), len(self.config.services_for_microcontroller),
                  self._stats_pub.resolved_name)

    # -- life cycle
    def close(self) -> None:
        """Stop the delivery thread, the services and the link; harmless twice."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._wake.set()
        thread = getattr(self, "_thread", None)
        if thread is not None:
            thread.join(timeout=2.0)
        for service in self._services:
            service.shutdown("mcu-bridge closed")
        for sub in self._subscribers:
            sub.unregister()
        self.link.close()

    def __enter__(self) -> "McuBridge":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- board -> ROS
    def _deliver_loop(self) -> None:
        next_stats = time.monotonic() + self.config.stats_period
        while not self._closed.is_set():
            self._wake.wait(_POLL)
            self._wake.clear()
            try:
                for stream in self._streams:
                    self._deliver(stream)
                    self._check_deadline(stream)
                if time.monotonic() >= next_stats:
                    next_stats = time.monotonic() + self.config.stats_period
                    self._publish_stats()
            except Exception as exc:  # a bug (or a stats_cb) must not end the delivery: counted, logged
                self.link.internal_error(exc, "in the bridge's delivery thread")

    def _deliver(self, stream: _FromStream) -> None:
        for payload, info in stream.reader.take(256):
            try:
                msg = stream.reader.decode(payload)
            except WireError as exc:
                self.link.bad_input(info["source"], exc, "a datagram")
                continue
            now = time.monotonic()
            resumed = stream.deadline.delivered(now)
            if resumed is not None:
                stream.in_silence = False
                _log.warning("micros_rt: mcu-bridge: %s: data from the microcontroller resumed after %.1f s of "
                             "silence (deadline %g s)", stream.entry.topic, resumed, stream.deadline.deadline)
            if not stream.time_filter.admit(now):
                self.stats.add("from_microcontroller", "filtered", entry=stream.entry.name)
                continue
            try:
                stream.publisher.publish(msg)
            except rospy.ROSSerializationException as exc:
                self.link.bad_input(info["source"], WireError("bad_field", f"{stream.entry.topic}: {exc}"),
                                    "a datagram")
                continue
            except (rospy.ROSException, micros_rt.MicrosRtError) as exc:
                if not rospy.is_shutdown():  # at shutdown the topic closes under us: nothing to say
                    self.link.warn(("publish", stream.entry.topic), f"mcu-bridge: cannot publish on "
                                   f"{stream.entry.topic}: {exc}", group="publish")
                continue
            self.stats.add("from_microcontroller", "published", entry=stream.entry.name)

    def _check_deadline(self, stream: _FromStream) -> None:
        now = time.monotonic()
        silent = stream.deadline.poll(now)
        if silent is None:
            return
        entry, board = stream.entry, self.config.microcontroller
        self.stats.add("from_microcontroller", "deadline_missed", entry=entry.name)
        # The first miss of a silence in words, then a reminder at most every _DEADLINE_REMINDER seconds:
        # a board that stays off must not fill the log (deadline_cb still hears every miss).
        if not stream.in_silence or now - stream.last_reminder >= _DEADLINE_REMINDER:
            stream.in_silence, stream.last_reminder = True, now
            _log.warning("micros_rt: mcu-bridge: %s: no %r datagram from the microcontroller %s for %.1f s, longer "
                         "than the deadline of %g s (%d misses so far); is the board running and sending to %s:%d?",
                         entry.topic, entry.name, board.address, silent, entry.subscribe.deadline,
                         stream.deadline.missed_total, self.config.bind.address, self.config.bind.topic_port)
        if self._deadline_cb is not None:
            try:
                self._deadline_cb(DeadlineMissed(entry.topic, entry.subscribe.deadline, silent,
                                                 stream.deadline.missed_total))
            except Exception:  # a user callback must not stop the bridge
                _log.exception("micros_rt: mcu-bridge: deadline_cb of %s raised", entry.topic)

    def _publish_stats(self) -> None:
        snapshot = self.snapshot()
        try:
            self._stats_pub.publish(String(data=json.dumps(snapshot, sort_keys=True)))
        except (rospy.ROSException, micros_rt.MicrosRtError) as exc:
            if not rospy.is_shutdown():
                self.link.warn(("publish", self.stats_topic), f"mcu-bridge: cannot publish {self.stats_topic}: {exc}",
                               group="publish")
        if self._stats_cb is not None:
            self._stats_cb(snapshot)

    def snapshot(self) -> Dict[str, Any]:
        """Every counter now (what ``~stats`` carries), with ``bad_input.total``."""
        snapshot = self.stats.snapshot()
        bad = snapshot.setdefault("bad_input", {})
        bad.pop("total", None)
        bad["total"] = sum(v for v in bad.values() if isinstance(v, int))
        return snapshot

    # -- services
    def _call_board(self, entry: ServiceEntry, request: Any) -> Any:
        """A ROS client calls a service the board serves."""
        response_class = entry.service_class._response_class
        params = wire.codec_for(entry.service_class._request_class).to_wire(request)
        try:
            answer = self.link.call(entry, params)
            response = wire.codec_for(response_class).from_wire(answer)
        except McuServiceError as exc:
            raise rospy.ServiceException(str(exc)) from exc
        except WireError as exc:
            self.stats.add("services_on_microcontroller", "failed", entry=entry.name)
            raise rospy.ServiceException(f"the microcontroller answered {entry.service} with a bad "
                                         f"{entry.type} response: {exc}") from exc
        self.stats.add("services_on_microcontroller", "ok", entry=entry.name)
        return response

    def _call_ros(self, entry: ServiceEntry, params: List[Any]) -> Dict[str, Any]:
        """The board calls a ROS service (on one of the link's call threads)."""
        request = wire.codec_for(entry.service_class._request_class).from_request(params)
        outcome: Dict[str, Any] = {}

        def call() -> None:
            try:
                outcome["response"] = rospy.ServiceProxy(entry.service, entry.service_class)(request)
            except Exception as exc:  # handed to the waiting thread, which reports it in words
                outcome["error"] = exc

        # rospy's ServiceProxy has no timeout of its own: the call runs on a thread we stop waiting for,
        # and at most _MAX_OUTSTANDING such threads may still be waiting on hung services.
        with self._outstanding_lock:
            if self._outstanding >= _MAX_OUTSTANDING:
                raise McuServiceError(f"{self._outstanding} earlier calls to ROS services are still unanswered; "
                                      f"refusing more until they return")
            self._outstanding += 1

        def run() -> None:
            try:
                call()
            finally:
                with self._outstanding_lock:
                    self._outstanding -= 1

        worker = threading.Thread(target=run, name=f"mcu-bridge call {entry.service}", daemon=True)
        worker.start()
        worker.join(entry.timeout)
        if worker.is_alive():
            raise McuServiceError(f"{entry.service} did not answer within {entry.timeout:g} s")
        if "error" in outcome:
            raise McuServiceError(f"{entry.service}: {outcome['error']}")
        return wire.codec_for(entry.service_class._response_class).to_wire(outcome["response"])


def _offer_callback(writer: UdpWriter) -> Callable[[Any], None]:
    def callback(msg: Any) -> None:
        writer.offer(msg)
    return callback
