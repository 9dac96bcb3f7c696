"""The bridge node: ROS topics and services on one side, the microcontroller link on the other.

A thin program on micros_rt's public API and the link's transport writer and reader:

- ROS -> board: a micros_rt subscription per ``to_microcontroller`` topic (``subscribe_with_qos``: the core
  applies its time filter and msg_valid_period and counts them); its callback prepares and sends one datagram
  through the link's :class:`~micros_rt.transports.mcu.link.UdpWriter`.
- board -> ROS: the link's :class:`~micros_rt.transports.mcu.link.UdpReader` feeds a subscription of its own
  (``subscribe_reader``: the core's time filter, deadline and queue rule, on its delivery thread) whose
  callback publishes on a micros_rt publication (``advertise_with_qos``: DDS to micros_rt nodes, TCPROS to
  stock ones, the entry's priority, latency budget and lifespan).
- services use rospy's own ``Service``/``ServiceProxy`` (``rosservice`` works).

The counters on ``~stats`` are the publications' and subscriptions' ``statistics()`` plus the link's wire
counters (datagrams sent, oversized, refused; bad input; service calls). No thread of the bridge's runs QoS:
one timer thread publishes the counters.

>>> micros_rt.init_node("mcu_bridge")                                  # doctest: +SKIP
>>> with McuBridge(load_config("mcu.yaml"), deadline_cb=print):        # doctest: +SKIP
...     micros_rt.spin()
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional

import genpy
import rospy
from std_msgs.msg import String

import micros_rt
from micros_rt.log import nonblocking_logger
from micros_rt.qos.options import MCU_FROM, MCU_TO, drop_counters

from ...transports.mcu import wire
from ...transports.mcu.spec import McuConfig, ServiceEntry, TopicEntry
from ...transports.mcu.errors import DatagramTooLargeError, McuServiceError, WireError
from ...transports.mcu.link import McuLink, UdpWriter

__all__ = ["McuBridge", "StatsCallback"]

_log = nonblocking_logger("rosout.micros_rt.mcu")

#: Called with every counters snapshot (the ``~stats`` content as a dict).
StatsCallback = Callable[[Dict[str, Any]], None]

_PUBLISH_QUEUE = 100   # ROS-side publisher of a board stream: keeps the newest 100, never blocks the bridge
_FROM_QUEUE = 1000     # board stream -> its publication: the newest 1,000 waiting (dropped_queue_full beyond)
_SUBSCRIBE_QUEUE = 10  # ROS-side subscriber of a topic for the board
_DEADLINE_REMINDER = 10.0  # seconds between log lines while a stream stays silent
_MAX_OUTSTANDING = 8   # board -> ROS calls whose ROS service has not answered yet

#: What each stream's subscription drops or misses, from the QoS catalogue: a board stream's applies the entry's
#: subscriber options, a topic to the board's its time filter and msg_valid_period (every option it takes).
#: In ``~stats`` each counter is named without ``dropped_`` (``filtered``, ``expired``, ``deadline_missed``).
_FROM_DROPS = drop_counters(side="subscribe", applies=MCU_FROM)
_TO_DROPS = drop_counters(applies=MCU_TO)


def _drops(stats: micros_rt.SubscriberStatistics, counters: tuple[str, ...]) -> Dict[str, int]:
    return {counter.removeprefix("dropped_"): getattr(stats, counter) for counter in counters}


@dataclass
class _Stream:
    """One configured topic: its ROS-side subscription, and for a board stream its publication."""

    entry: TopicEntry
    subscriber: micros_rt.Subscriber
    publisher: Optional[micros_rt.Publisher] = None


class McuBridge:
    """Runs one microcontroller link inside the current node (call :func:`micros_rt.init_node` first).

    - ``deadline_cb``: called with a :class:`micros_rt.DeadlineMissed` when a ``from_microcontroller`` stream
      with a ``deadline`` goes silent, once per deadline of silence (micros_rt's deadline monitor).
    - ``stats_cb``: called with the counters every ``stats_period`` seconds (also published, as JSON in a
      ``std_msgs/String``, on ``~stats``).

    Raises :class:`micros_rt.TransportError` when a socket cannot be bound. ``close()`` (or leaving the
    ``with`` block) stops everything; it is harmless twice.
    """

    def __init__(self, config: McuConfig, *, deadline_cb: Optional[Callable[[Any], None]] = None,
                 stats_cb: Optional[StatsCallback] = None) -> None:
        self.config = config
        self._deadline_cb = deadline_cb
        self._stats_cb = stats_cb
        self._closed = threading.Event()
        self._from: List[_Stream] = []
        self._to: List[_Stream] = []
        self._services: List[rospy.Service] = []
        self._outstanding = 0
        self._outstanding_lock = threading.Lock()
        self._last_reminder: Dict[str, float] = {}
        self.link = McuLink(config)
        self.stats = self.link.stats
        try:
            self._open()
        except BaseException:
            self.close()
            raise
        self._thread = threading.Thread(target=self._stats_loop, name="mcu-bridge stats", daemon=True)
        self._thread.start()

    def _open(self) -> None:
        nh = micros_rt.NodeHandle()
        for entry in self.config.from_microcontroller:
            publisher = nh.advertise_with_qos(entry.topic, entry.data_class, _PUBLISH_QUEUE, entry.advertise)
            qos = entry.subscribe if math.isinf(entry.subscribe.deadline) else \
                dataclasses.replace(entry.subscribe, deadline_cb=functools.partial(self._deadline_missed, entry))
            subscriber = nh.subscribe_reader(entry.topic, entry.data_class,
                                             functools.partial(self.link.open_reader, entry),
                                             functools.partial(self._publish, entry, publisher), _FROM_QUEUE, qos)
            self._from.append(_Stream(entry, subscriber, publisher))
        # Any publisher on the ROS side is welcome (best effort or reliable, stamped or not): the link is the
        # narrow part. The core applies the entry's time filter and msg_valid_period before the callback sends.
        for entry in self.config.to_microcontroller:
            writer = self.link.open_writer(entry)
            ros_side = micros_rt.SubscribeQoSOptions(using_best_effort_protocol=True,
                                                     ordered_by_sending_timestamp=False,
                                                     time_filter_duration=entry.subscribe.time_filter_duration)
            subscriber = nh.subscribe_with_qos(entry.topic, entry.data_class, functools.partial(self._send, writer),
                                               _SUBSCRIBE_QUEUE, ros_side,
                                               msg_valid_period=entry.advertise.msg_valid_period)
            self._to.append(_Stream(entry, subscriber))
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
        """Stop the subscriptions, the services, the counters' timer and the link; harmless twice."""
        if self._closed.is_set():
            return
        self._closed.set()
        thread = getattr(self, "_thread", None)
        if thread is not None:
            thread.join(timeout=2.0)
        for service in self._services:
            service.shutdown("mcu-bridge closed")
        for stream in self._from + self._to:
            stream.subscriber.unregister()
        self.link.close()

    def __enter__(self) -> "McuBridge":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- ROS -> board (a micros_rt delivery thread, after the core's admission path)
    def _send(self, writer: UdpWriter, msg: Any) -> None:
        topic = writer.entry.topic
        try:
            writer.send(writer.prepare(msg))
        except DatagramTooLargeError as exc:
            self.link.warn(("oversized", topic), f"microcontroller link: {exc}", group="oversized")
        except genpy.SerializationError as exc:
            self.link.warn(("bad_message", topic), f"microcontroller link: {topic}: cannot encode the message: "
                           f"{exc}", group="bad_message")
        except micros_rt.TransportError as exc:
            self.link.warn(("send_failed", topic), f"microcontroller link: {topic}: {exc}", group="send_failed")

    # -- board -> ROS (a micros_rt delivery thread, after the core's admission path)
    def _publish(self, entry: TopicEntry, publisher: micros_rt.Publisher, msg: Any) -> None:
        try:
            publisher.publish(msg)
        except rospy.ROSSerializationException as exc:
            self.link.bad_input(self.config.microcontroller.address, WireError("bad_field", f"{entry.topic}: {exc}"),
                                "a datagram")
        except (rospy.ROSException, micros_rt.MicrosRtError) as exc:
            if not rospy.is_shutdown():  # at shutdown the topic closes under us: nothing to say
                self.link.warn(("publish", entry.topic), f"mcu-bridge: cannot publish on {entry.topic}: {exc}",
                               group="publish")

    def _deadline_missed(self, entry: TopicEntry, missed: Any) -> None:
        """micros_rt's deadline monitor found the stream silent: say it in the link's words (the first miss of
        a silence, then at most every _DEADLINE_REMINDER seconds), then tell ``deadline_cb`` (every miss)."""
        now = time.monotonic()
        first = missed.silent_for < 2 * missed.deadline
        if first or now - self._last_reminder.get(entry.name, 0.0) >= _DEADLINE_REMINDER:
            self._last_reminder[entry.name] = now
            board = self.config.microcontroller
            _log.warning("micros_rt: mcu-bridge: %s: no %r datagram from the microcontroller %s for %.1f s, longer "
                         "than the deadline of %g s (%d misses so far); is the board running and sending to %s:%d?",
                         entry.topic, entry.name, board.address, missed.silent_for, missed.deadline,
                         missed.total_count, self.config.bind.address, self.config.bind.topic_port)
        if self._deadline_cb is not None:
            self._deadline_cb(missed)  # micros_rt logs (and survives) a callback that raises

    # -- counters
    def _stats_loop(self) -> None:
        while not self._closed.wait(self.config.stats_period):
            try:
                self._publish_stats()
            except Exception as exc:  # a bug (or a stats_cb) must not end the counters: counted, logged
                self.link.internal_error(exc, "in the bridge's counters thread")

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
        """Every counter now (what ``~stats`` carries): each stream's from its micros_rt publication and
        subscription, the link's wire counters, and ``bad_input.total``."""
        snapshot = self.stats.snapshot()
        wire_to = snapshot.pop("to_microcontroller", {})
        from_board: Dict[str, Any] = {}
        for stream in self._from:
            sub = stream.subscriber.statistics()
            assert stream.publisher is not None
            from_board[stream.entry.name] = {
                "received": sub.received, "published": stream.publisher.statistics().published,
                "dropped_queue_full": sub.dropped_queue_full, **_drops(sub, _FROM_DROPS)}
        to_board: Dict[str, Any] = {}
        for stream in self._to:
            to_board[stream.entry.name] = {**wire_to.get(stream.entry.name, {}),
                                           **_drops(stream.subscriber.statistics(), _TO_DROPS)}
        if from_board:
            snapshot["from_microcontroller"] = from_board
        if to_board:
            snapshot["to_microcontroller"] = to_board
        bad = snapshot.setdefault("bad_input", {})
        bad.pop("total", None)
        bad["total"] = sum(v for v in bad.values() if isinstance(v, int))
        return snapshot

    # -- services
    def _call_board(self, entry: ServiceEntry, request: Any) -> Any:
        """A ROS client calls a service the board serves. The board's answer, in any era's form (a map, an
        array, a bare value or nil), is read by :meth:`wire.MessageCodec.from_answer`; what it could not put in
        the response is logged (once per service, then counted in the rate-limited summary)."""
        response_class = entry.service_class._response_class
        params = wire.codec_for(entry.service_class._request_class).to_wire(request)
        try:
            answer = self.link.call(entry, params)
            read = wire.codec_for(response_class).from_answer(answer)
        except McuServiceError as exc:
            raise rospy.ServiceException(str(exc)) from exc
        except WireError as exc:
            self.stats.add("services_on_microcontroller", "failed", entry=entry.name)
            raise rospy.ServiceException(f"the microcontroller answered {entry.service} with a bad "
                                         f"{entry.type} response: {exc}") from exc
        if read.note is not None:
            self.link.warn(("answer", entry.name), f"microcontroller link: {entry.service} ({entry.name!r}): "
                           f"{read.note}", group="answer")
        self.stats.add("services_on_microcontroller", "ok", entry=entry.name)
        return read.response

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

