"""The bridge node: mqtt_client's behaviour (ROS 1) on micros_rt's publish/subscribe.

ROS -> MQTT: each ``bridge.ros2mqtt`` topic is subscribed as soon as the master knows its type, and every
message is sent to the broker in mqtt_client's framing (its type announced, retained, on
``mqtt_client/ros_msg_type/<mqtt_topic>``), as primitive text or as JSON. A framed topic is taken as bytes
(stock rospy's ``AnyMsg`` over TCPROS, from stock and micros_rt publishers alike, as mqtt_client's
ShapeShifter): its bytes are the payload, nothing is deserialized. Primitive and JSON topics need the fields
and are subscribed with micros_rt (DDS from micros_rt publishers, TCPROS from stock nodes). The framing
is one mqtt_client generation per topic: the peers' on the broker, or ``bridge/mqtt_client_version``
(see :mod:`micros_rt.transports.mqtt.generations`).

MQTT -> ROS: each ``bridge.mqtt2ros`` topic is published with micros_rt once its type is known: from the
announcement (an installed class when the md5 matches, else a class built from the announced
definition), from ``ros_type``, or from the first primitive text. Either generation is read, whatever
this bridge writes: the announcement's length says which (2.x has ``stamped``), and the topic's payloads are
read in the form it announces. Unlike mqtt_client, the data topic is subscribed from the start and
messages that arrive before their type announcement are held (up to :data:`PENDING_LIMIT` per topic), so
the first message is never lost.

Bad input (a payload that does not decode, an unknown type, a text that does not fit the topic's type,
a message too large to send) is logged once per topic and kind in words, then counted; the node keeps
running. :meth:`MqttBridge.counters` has the counts; they are logged on close.
"""

from __future__ import annotations

import collections
import io
import queue
import threading
import time
import uuid
from typing import Any, Callable, Deque, Dict, Optional, Tuple, Type

import genmsg  # type: ignore[import-untyped]
import genmsg.gentools  # type: ignore[import-untyped]
import genmsg.msg_loader  # type: ignore[import-untyped]
import genpy
import genpy.dynamic
import roslib.message
import rospy
from std_msgs.msg import Float64

import micros_rt

from ...log import nonblocking_logger
from ...ratelimit import RateLimitedLog
from ...transports.mqtt import codec
from ...transports.mqtt.client import MqttConnection
from ...transports.mqtt.generations import ANNOUNCEMENTS, PeerGenerations
from .params import Mqtt2RosParams, MqttParams, Ros2MqttParams

__all__ = ["MqttBridge", "PENDING_LIMIT", "is_connected_service_class"]

_log = nonblocking_logger("rosout.micros_rt.mqtt")

#: Messages held per MQTT topic while its ROS type is not yet known.
PENDING_LIMIT = 100
#: How often the master is asked for the types of ROS topics not yet subscribed (seconds).
RESOLVE_INTERVAL = 0.3
#: How long a new ROS publisher waits for the subscribers the master knows (seconds).
SUBSCRIBER_WAIT = 5.0
#: How long (seconds after the first connect) a topic written in the peers' generation holds its messages
#: while no mqtt_client peer has announced a type on the broker; then it writes the default (2.x).
PEER_HOLD = 10.0
#: Messages a topic holds meanwhile (the oldest are dropped beyond, counted ``held_dropped``).
HOLD_LIMIT = 1000
#: Seconds between two looks at the broker's retained type announcements (a scan: the bridge subscribes
#: ``mqtt_client/ros_msg_type/#`` until the broker has shown them, then unsubscribes), so that a peer's
#: repetition of its announcement with every message costs nothing in between.
SCAN_INTERVAL = 2.0
#: A scan whose end marker did not come back within this many seconds is started again.
SCAN_TIMEOUT = 5.0


#: The package of mqtt_client's ``IsConnected`` service in each generation (2.x moved it).
IS_CONNECTED_PACKAGE = {codec.WireGeneration.V1: "mqtt_client", codec.WireGeneration.V2: "mqtt_client_interfaces"}
#: ``IsConnected``'s md5 (empty request, ``bool connected``): the same in both generations.
IS_CONNECTED_MD5 = "e0cdaf65159c7f3563426650fb8d3f64"


def installed_is_connected_package(preferred: codec.WireGeneration = codec.WireGeneration.V2) -> Optional[str]:
    """The package whose ``IsConnected`` service type is installed here (what ``rosservice`` can load):
    ``mqtt_client_interfaces`` (mqtt_client 2.x) or ``mqtt_client`` (1.x); the ``preferred`` generation's
    when both are; None when neither is."""
    found = []
    for wire in (preferred, *(w for w in codec.WireGeneration if w is not preferred)):
        pkg = IS_CONNECTED_PACKAGE[wire]
        try:
            cls = roslib.message.get_service_class(f"{pkg}/IsConnected")
        except Exception:   # a broken package on the path counts as not installed
            cls = None
        if cls is not None and getattr(cls, "_md5sum", "") == IS_CONNECTED_MD5:
            found.append(pkg)
    return found[0] if found else None


def is_connected_service_class(wire: codec.WireGeneration = codec.WireGeneration.V2, *,
                               package: Optional[str] = None) -> Type[Any]:
    """mqtt_client's ``IsConnected`` service (empty request, ``bool connected``), built at run time with
    mqtt_client's md5 so that its own clients can call this node. The type is ``<package>/IsConnected``:
    ``mqtt_client_interfaces`` in 2.x, ``mqtt_client`` in 1.x (same md5); ``package`` when given."""
    pkg = package or IS_CONNECTED_PACKAGE[wire]
    ctx = genmsg.MsgContext.create_default()
    spec = genmsg.msg_loader.load_srv_from_string(ctx, "---\nbool connected\n", f"{pkg}/IsConnected")
    request = genpy.dynamic.generate_dynamic(f"{pkg}/IsConnectedRequest", "")[f"{pkg}/IsConnectedRequest"]
    response = genpy.dynamic.generate_dynamic(f"{pkg}/IsConnectedResponse",
                                              "bool connected\n")[f"{pkg}/IsConnectedResponse"]

    class IsConnected:
        _type = f"{pkg}/IsConnected"
        _md5sum = genmsg.gentools.compute_md5(ctx, spec)
        _request_class = request
        _response_class = response

    return IsConnected


class _Problems:
    """Bad input: the first of each (topic, kind) in words, then counted (and summarised every 30 s)."""

    def __init__(self) -> None:
        self._log = RateLimitedLog(_log, interval=30.0)
        self._lock = threading.Lock()
        self.counts: Dict[str, int] = collections.Counter()

    def report(self, topic: str, kind: str, text: str) -> None:
        with self._lock:
            self.counts[kind] += 1
        self._log.warning((topic, kind), text)


class _Ros2Mqtt:
    """One ROS topic sent to the broker.

    Its type announcement (retained, ``mqtt_client/ros_msg_type/<mqtt_topic>``) is published when the type
    is first known, after every (re)connect and when the generation written changes; it counts as sent only
    when the connection took it (sent, or kept in the disk buffer), else the next message tries again."""

    def __init__(self, bridge: "MqttBridge", p: Ros2MqttParams) -> None:
        self.bridge, self.p = bridge, p
        self.subscriber: Optional[micros_rt.Subscriber] = None
        self.raw_subscriber: Optional[rospy.Subscriber] = None
        self.data_class: Optional[Type[genpy.Message]] = None
        self.framed = not (p.primitive or p.json)   # mqtt_client framing: a type announcement, a generation
        self.wire, self.why = bridge.generations.decide(p.mqtt_topic)
        self._lock = threading.Lock()
        self._type: Optional[codec.RosMsgType] = None          # the type last sent
        self._announcement: Tuple[Any, bytes] = (None, b"")    # ((md5, wire), its bytes) cached
        self.announced: Optional[bytes] = None   # the announcement the current connection took (None: none yet)
        self._built: Dict[str, Type[genpy.Message]] = {}
        self.sent = 0
        # following the peers and none known yet: messages wait (HOLD_LIMIT) for a peer's generation, so that
        # nothing is written that one generation would misread (a 1.x mqtt_client reads a 2.x payload's first
        # byte as its flag); PEER_HOLD after the first connect the default is written
        self.holding = self.framed and not bridge.generations.knows(p.mqtt_topic)
        self._held: Deque[Tuple[bytes, Optional[genpy.Time]]] = collections.deque()
        self._send_lock = threading.RLock()
        self.held = 0            # messages that waited for a peer's generation
        self.held_dropped = 0    # ... and were dropped beyond HOLD_LIMIT

    @property
    def announced_md5(self) -> str:
        """The md5 of the announcement the current connection took ('' when none)."""
        return self._type.md5 if self._type is not None and self.announced is not None else ""

    def attach(self, data_class: Type[genpy.Message]) -> None:
        self.data_class = data_class
        self.subscriber = self.bridge.nh.subscribe(self.p.ros_topic, data_class, self.on_ros, self.p.queue_size)
        _log.info("micros_rt mqtt: ROS topic '%s' (%s) subscribed", self.p.ros_topic, data_class._type)

    def attach_raw(self, type_name: str, *, installed: bool) -> None:
        """Take the serialized bytes (stock rospy's AnyMsg over TCPROS, as mqtt_client's ShapeShifter) and the
        type from the connection header: every framed topic, and any topic whose type is not installed."""
        self.raw_subscriber = rospy.Subscriber(self.p.ros_topic, rospy.AnyMsg, self.on_raw,
                                               queue_size=self.p.queue_size)
        _log.info("micros_rt mqtt: ROS topic '%s' (%s, %s) subscribed", self.p.ros_topic, type_name,
                  "bridged as its serialized bytes, as mqtt_client's ShapeShifter" if installed else
                  "not installed here: bridged as its serialized bytes")

    def on_raw(self, raw: Any) -> None:
        header = getattr(raw, "_connection_header", None) or {}
        t = self._type
        if t is None or t.md5 != header.get("md5sum", ""):
            t = codec.RosMsgType(header.get("md5sum", ""), header.get("type", ""),
                                 header.get("message_definition", ""))
        msg = None
        if self.p.primitive or self.p.json:
            try:
                cls = self._built.get(t.md5) or _message_class(t)
                self._built[t.md5] = cls
                msg = cls()
                msg.deserialize(raw._buff)
            except Exception as exc:  # genmsg/genpy: a definition or payload that does not parse
                self.bridge.problems.report(self.p.ros_topic, "unknown_type", f"ROS topic {self.p.ros_topic}: "
                                            f"cannot decode {t.name} from its connection header: {exc}")
                return
        self._send(t, raw._buff, msg)

    def on_ros(self, msg: genpy.Message) -> None:
        t = self._type
        if t is None or t.md5 != msg._md5sum:
            t = codec.RosMsgType.of(type(msg))
        self._send(t, None, msg)

    # -- the type announcement

    def _announcement_bytes(self, t: codec.RosMsgType, wire: codec.WireGeneration) -> bytes:
        key, raw = self._announcement
        if key != (t.md5, wire):
            raw = codec.encode_msg_type(t.for_wire(wire, stamped=self.p.inject_timestamp))
            self._announcement = ((t.md5, wire), raw)
        return raw

    def announce(self, *, force: bool = False) -> None:
        """Publish the type announcement (retained) in the generation written now, unless the current
        connection already took this one (``force``: even so, after a reconnect or a change)."""
        with self._lock:
            t = self._type
            if t is None or not self.framed:
                return
            if not self.bridge.connection.can_send:
                self.announced = None   # dropped if tried now: sent once the connection is up (on_live)
                return
            raw = self._announcement_bytes(t, self.wire)
            if raw == self.announced and not force:
                return
            self.bridge.generations.published(self.p.mqtt_topic, raw)
            if self.bridge.connection.publish(codec.ROS_MSG_TYPE_PREFIX + self.p.mqtt_topic, raw, qos=self.p.qos,
                                              retain=True):
                self.announced = raw
            else:
                self.announced = None   # not sent (not connected yet, buffer full): the next message retries

    def redecide(self) -> None:
        """Follow the peers on the broker: a new generation is logged and announced at once (and a topic that
        held its messages for a peer's generation sends them)."""
        if self.holding:
            if self.bridge.generations.knows(self.p.mqtt_topic):
                self.release()
            return
        wire, why = self.bridge.generations.decide(self.p.mqtt_topic)
        with self._lock:
            changed = wire is not self.wire
            self.wire, self.why = wire, why
        if changed and self.framed:
            _log.info("micros_rt mqtt: MQTT topic '%s': now writing mqtt_client %s (%s)", self.p.mqtt_topic,
                      wire.label, why)
            self.announce()

    def release(self, expired: bool = False) -> None:
        """Stop holding: decide the generation, announce it and send the held messages in it, oldest first."""
        with self._send_lock:
            self._release(expired)

    def _release(self, expired: bool) -> None:
        with self._lock:
            if not self.holding:
                return
            self.holding = False
            held, self._held = list(self._held), collections.deque()
        wire, why = self.bridge.generations.decide(self.p.mqtt_topic)
        with self._lock:
            self.wire, self.why = wire, why
        if expired:
            _log.warning("micros_rt mqtt: MQTT topic '%s': no mqtt_client peer announced a type on the broker within "
                         "%g s: writing mqtt_client %s (the default). A 1.x mqtt_client that only reads this topic "
                         "announces nothing and would misread it: give it bridge/mqtt_client_version: 1 (or "
                         "mqtt_client_version: 1 on this topic)", self.p.mqtt_topic, PEER_HOLD, wire.label)
        else:
            _log.info("micros_rt mqtt: MQTT topic '%s': writing mqtt_client %s (%s)%s", self.p.mqtt_topic,
                      wire.label, why, f"; the {len(held)} messages held until now follow" if held else "")
        self.announce()
        for serialized, stamp in held:
            self._publish(codec.encode_ros_payload(serialized, wire=self.wire, stamp=stamp))
        self.bridge.end_watch()

    def check_hold(self, now: float, live_since: Optional[float]) -> None:
        """Release the held messages PEER_HOLD seconds after the first connect (the scan thread)."""
        if self.holding and live_since is not None and now - live_since >= PEER_HOLD:
            self.release(expired=True)

    def _hold(self, serialized: bytes, stamp: Optional[genpy.Time]) -> bool:
        """Hold one message while the peers' generation is unknown; False when no longer holding."""
        with self._lock:
            if not self.holding:
                return False
            self._held.append((serialized, stamp))
            self.held += 1
            if len(self._held) > HOLD_LIMIT:
                self._held.popleft()
                self.held_dropped += 1
                dropped = self.held_dropped
            else:
                return True
        self.bridge.problems.report(self.p.mqtt_topic, "held_dropped",
                                    f"MQTT topic '{self.p.mqtt_topic}': no peer's mqtt_client generation known yet; "
                                    f"holding the newest {HOLD_LIMIT} messages, dropped older ones ({dropped} in "
                                    f"all; bridge/mqtt_client_version fixes the generation)")
        return True

    def _send(self, t: codec.RosMsgType, serialized: Optional[bytes], msg: Optional[genpy.Message]) -> None:
        p = self.p
        if p.primitive and msg is not None:
            payload = codec.msg_to_text(msg).encode("utf-8")
        elif p.json and msg is not None:
            payload = codec.msg_to_json(msg).encode("utf-8")
        else:
            if serialized is None:
                assert msg is not None
                buf = io.BytesIO()
                msg.serialize(buf)
                serialized = buf.getvalue()
            stamp = genpy.Time.from_sec(time.time()) if p.inject_timestamp else None
            with self._send_lock:     # after the held ones, never between them
                if self.announced is None or t is not self._type:
                    with self._lock:
                        self._type = t
                    # announced even while holding: no data follows it yet, and a micros_rt bridge on the other
                    # side, holding too, learns a peer's generation from it
                    self.announce()
                # held only when it could be sent now: while disconnected (no disk buffer) it is dropped, counted
                if self.holding and self.bridge.connection.can_send and self._hold(serialized, stamp):
                    return
                self._publish(codec.encode_ros_payload(serialized, wire=self.wire, stamp=stamp))
            return
        self._publish(payload)

    def _publish(self, payload: bytes) -> None:
        p = self.p
        conn = self.bridge.connection
        try:
            if conn.publish(p.mqtt_topic, payload, qos=p.qos, retain=p.retained):
                self.sent += 1
        except ValueError as exc:   # paho: payload above MQTT's 256 MB limit
            self.bridge.problems.report(p.ros_topic, "too_large",
                                        f"ROS topic {p.ros_topic}: a {len(payload)}-byte message cannot be sent to "
                                        f"MQTT topic '{p.mqtt_topic}': {exc}")


#: Messages of one MQTT topic that wait for its worker thread (the oldest are dropped beyond, counted).
WORKER_BACKLOG = 1000


class _TopicWorker:
    """One MQTT topic's handling, in arrival order, on a thread of its own instead of paho's network thread.

    Handling a type announcement advertises the ROS topic: that registers with the master and waits (up to
    SUBSCRIBER_WAIT) for the subscribers it lists; publishing can wait on a lossless ROS subscriber. On
    paho's thread, which every MQTT topic of the bridge shares, either stalled all of them."""

    def __init__(self, name: str, on_overflow: Callable[[int], None]) -> None:
        self.name = name
        self._items: Deque[Tuple[Callable[..., None], Tuple[Any, ...], bool]] = collections.deque()
        self._lock = threading.Lock()
        # the worker sleeps in SimpleQueue.get (C), woken by one token when it went idle: per message that is
        # cheaper than a Condition, whose wait allocates a lock and whose notify runs in Python
        self._wake: "queue.SimpleQueue[None]" = queue.SimpleQueue()
        self._idle = False
        self._thread: Optional[threading.Thread] = None
        self._closed = False
        self._running = False    # the worker is handling an item
        self._on_overflow = on_overflow
        self.dropped = 0
        self.inline = 0          # items handled on the caller's thread (nothing queued or under way)

    def run_inline(self, fn: Callable[..., None], *args: Any) -> bool:
        """From paho's thread (the only one that puts): handle ``fn(*args)`` here when nothing is queued or under
        way, so order is kept and a message costs no thread hand-over; False (nothing done) otherwise."""
        with self._lock:
            if self._closed:
                return True
            if self._items or self._running:
                return False
        fn(*args)
        self.inline += 1
        return True

    def put(self, fn: Callable[..., None], *args: Any, droppable: bool = True) -> None:
        """From paho's thread: never waits. Beyond WORKER_BACKLOG the oldest droppable item goes, counted."""
        with self._lock:
            if self._closed:
                return
            self._items.append((fn, args, droppable))
            if len(self._items) > WORKER_BACKLOG:
                for i, (_fn, _args, may_drop) in enumerate(self._items):
                    if may_drop:
                        del self._items[i]
                        self.dropped += 1
                        self._on_overflow(self.dropped)
                        break
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=f"micros_rt mqtt {self.name}", daemon=True)
                self._thread.start()
            wake, self._idle = self._idle, False
        if wake:
            self._wake.put(None)

    def _run(self) -> None:
        while True:
            with self._lock:
                self._running = False
                if self._closed:
                    return
                if not self._items:
                    self._idle = True
                    item = None
                else:
                    item = self._items.popleft()
                    self._running = True
            if item is None:
                self._wake.get()
                continue
            fn, args, _ = item
            try:
                fn(*args)
            except Exception:
                _log.exception("micros_rt mqtt: handling a message of MQTT topic '%s' failed (continuing)", self.name)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._items.clear()
            wake, self._idle = self._idle, False
        if wake:
            self._wake.put(None)
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)


class _Mqtt2Ros:
    """One MQTT topic published on ROS."""

    def __init__(self, bridge: "MqttBridge", p: Mqtt2RosParams) -> None:
        self.bridge, self.p = bridge, p
        self.lock = threading.Lock()
        self.publisher: Optional[micros_rt.Publisher] = None
        self.data_class: Optional[Type[genpy.Message]] = None
        self.md5 = ""
        self.announced = False               # a type announcement was accepted: the payload form is known
        self.stamped: Optional[bool] = None  # its stamped field (None: 1.x, payloads carry a flag byte)
        self.type_fed = b""                  # the announcement last handed to the worker (paho's thread only)
        self.pending: Deque[bytes] = collections.deque()
        self.latency_pub: Optional[micros_rt.Publisher] = None
        self.delivered = 0
        self.retyped = 0                     # primitive texts of another kind re-advertised the ROS topic
        self.worker = _TopicWorker(p.mqtt_topic, lambda n: bridge.problems.report(
            p.mqtt_topic, "backlog", f"MQTT topic '{p.mqtt_topic}': more than {WORKER_BACKLOG} messages waited for "
                                     f"the ROS side; dropped the oldest ({n} in all)"))
        if p.ros_type:
            cls = roslib.message.get_message_class(p.ros_type)
            if cls is None:
                raise micros_rt.TypeMappingError(
                    f"bridge/mqtt2ros: ros_type '{p.ros_type}' of MQTT topic '{p.mqtt_topic}' is not an installed "
                    "ROS message type")
            self._advertise(cls)

    # -- ROS side

    def _advertise(self, cls: Type[genpy.Message]) -> None:
        if self.publisher is not None:
            self.publisher.unregister()
        self.publisher = self.bridge.nh.advertise(self.p.ros_topic, cls, self.p.queue_size, latch=self.p.latched)
        self.data_class, self.md5 = cls, cls._md5sum
        _log.info("ROS publisher message type on topic '%s' set to '%s'", self.p.ros_topic, cls._type)
        _await_subscribers(self.publisher)


    def _publish(self, msg: genpy.Message) -> None:
        assert self.publisher is not None
        self.publisher.publish(msg)
        self.delivered += 1

    def _latency(self, stamp: genpy.Time) -> None:
        if self.latency_pub is None:
            self.latency_pub = self.bridge.nh.advertise("~latencies/" + self.p.ros_topic.lstrip("/"), Float64, 1)
        self.latency_pub.publish(Float64(data=time.time() - stamp.to_sec()))

    # -- MQTT side: paho's network thread hands over (never waits), the worker handles in order

    def feed_type(self, topic: str, payload: bytes, properties: Any = None) -> None:
        if payload == self.type_fed:
            return    # mqtt_client repeats its announcement with every message: the same one changes nothing
        self.type_fed = payload
        self.worker.put(self.on_type, topic, payload, droppable=False)

    def feed_data(self, topic: str, payload: bytes, properties: Any = None) -> None:
        # a payload that only decodes and publishes (type known, no publisher to advertise, a ROS queue that
        # never blocks) is handled on paho's thread when the worker is idle: no hand-over per message
        if self.fast and self.worker.run_inline(self.on_data, topic, payload):
            return
        self.worker.put(self.on_data, topic, payload)

    @property
    def fast(self) -> bool:
        return (self.announced and self.publisher is not None and self.p.queue_size is not None
                and not (self.p.primitive or self.p.json) and (self.stamped is False or self.latency_pub is not None))

    def on_type(self, topic: str, payload: bytes, properties: Any = None) -> None:
        problems = self.bridge.problems
        try:
            announced = codec.decode_msg_type(payload)
        except codec.CodecError as exc:
            problems.report(topic, "bad_type", f"MQTT topic '{topic}': type announcement does not decode: {exc}")
            return
        with self.lock:
            if self.p.ros_type and announced.name != self.p.ros_type:
                problems.report(topic, "type_mismatch",
                                f"MQTT topic '{self.p.mqtt_topic}' announces {announced.name}, but ros_type is "
                                f"{self.p.ros_type}: its messages are dropped")
                self.md5, self.announced = "", False
                return
            if announced.md5 != self.md5:
                try:
                    cls = _message_class(announced)
                except Exception as exc:  # genmsg/genpy raise several kinds for a bad definition
                    problems.report(topic, "unknown_type", f"MQTT topic '{self.p.mqtt_topic}': cannot build ROS "
                                    f"type {announced.name} from its announced definition: {exc}")
                    return
                self._advertise(cls)
            if not self.announced or self.stamped != announced.stamped:
                _log.info("MQTT topic '%s': peer speaks mqtt_client %s%s", self.p.mqtt_topic, announced.wire.label,
                          "" if announced.stamped is None else
                          (", stamped" if announced.stamped else ", not stamped"))
            self.announced, self.stamped = True, announced.stamped
            pending, self.pending = list(self.pending), collections.deque()
        self.bridge.note_read_generation(self.p.mqtt_topic, announced.wire)
        self.bridge.connection.unsubscribe(codec.ROS_MSG_TYPE_PREFIX + self.p.mqtt_topic)  # scans show changes
        for data in pending:
            self.on_data(self.p.mqtt_topic, data)

    def on_data(self, topic: str, payload: bytes, properties: Any = None) -> None:
        p = self.p
        if p.primitive or p.json:
            self._on_text(topic, payload)
            return
        with self.lock:
            cls, stamped = self.data_class, self.stamped
            if cls is None or not self.announced:
                if len(self.pending) >= PENDING_LIMIT:
                    self.pending.popleft()
                    self.bridge.problems.report(topic, "no_type",
                                                f"MQTT topic '{topic}': no ROS type announced yet on "
                                                f"'{codec.ROS_MSG_TYPE_PREFIX}{topic}'; holding the newest "
                                                f"{PENDING_LIMIT} messages, dropping older ones")
                self.pending.append(payload)
                return
        try:
            stamp, body = codec.decode_ros_payload(payload, stamped=stamped)
            msg = cls()
            raw = bytes(body)
            msg.deserialize(raw)
            _check_length(msg, raw)
        except Exception as exc:  # genpy raises struct.error, DeserializationError, UnicodeDecodeError...
            self.bridge.request_scan()    # the peer may have announced another type since the last scan
            self.bridge.problems.report(topic, "malformed",
                                        f"MQTT topic '{topic}': a {len(payload)}-byte payload does not decode as "
                                        f"mqtt_client {'1.x' if stamped is None else '2.x'}'s {cls._type}: "
                                        f"{exc or type(exc).__name__}")
            return
        if stamp is not None:
            self._latency(stamp)
        self._publish(msg)

    def _on_text(self, topic: str, payload: bytes) -> None:
        p = self.p
        try:
            text = payload.decode("utf-8")
        except UnicodeDecodeError:
            self.bridge.problems.report(topic, "malformed", f"MQTT topic '{topic}': payload is not UTF-8 text "
                                        f"({len(payload)} bytes)")
            return
        try:
            with self.lock:
                if p.json:
                    assert self.data_class is not None
                    msg = codec.json_to_msg(text, self.data_class)
                elif not p.ros_type:
                    # as mqtt_client: each text is probed, and a text of another kind than the last one
                    # re-advertises the ROS topic with its type (42, abc, 1.5, True: Int32, String, Float32, Bool)
                    msg = codec.probe_primitive(text)
                    if type(msg) is not self.data_class:
                        if self.data_class is not None:
                            self.retyped += 1
                            _log.info("MQTT topic '%s': primitive text %s is a %s, the last was a %s: ROS topic '%s' "
                                      "re-advertised as %s (as mqtt_client does; ros_type fixes one type)",
                                      topic, _short_text(text), msg._type, self.data_class._type, p.ros_topic,
                                      msg._type)
                        self._advertise(type(msg))
                else:
                    assert self.data_class is not None   # ros_type: advertised at start
                    msg = codec.text_to_msg(text, self.data_class)
        except codec.CodecError as exc:
            self.bridge.problems.report(topic, "unfit_text", f"MQTT topic '{topic}' -> ROS topic '{p.ros_topic}': "
                                        f"{exc}")
            return
        self._publish(msg)


def _short_text(text: str) -> str:
    return repr(text if len(text) <= 40 else text[:40] + "...")


def _check_length(msg: genpy.Message, body: bytes) -> None:
    """genpy trusts length prefixes: a string or array claiming more bytes than the buffer holds is read
    short without complaint. A payload is well-formed only when its message serializes back to it.
    Compared as bytes (memcmp): a memoryview compares item by item, 4.7 ms for a 640x480 rgb8 image."""
    buf = io.BytesIO()
    msg.serialize(buf)
    if buf.tell() != len(body) or buf.getvalue() != body:
        raise ValueError(f"its {len(body)}-byte body does not re-encode to the same bytes (a length prefix "
                         f"does not match the data, or trailing bytes)")


def _await_subscribers(pub: micros_rt.Publisher, *, timeout: float = SUBSCRIBER_WAIT) -> None:
    """Wait (bounded) until each subscriber node the master lists for a new publisher's topic is reached, so
    that the first message, published right after advertising, reaches them (mqtt_client loses it). By node,
    not by count: the bridge's own subscriber of the topic (a ros2mqtt entry) connects first and would make a
    count of one look like the listed subscriber's."""
    try:
        _, subscribers, _ = rospy.get_master().getSystemState()[2]
    except Exception as exc:  # master away: publish anyway
        _log.debug("micros_rt mqtt: cannot ask the master for subscribers: %s", exc)
        return
    expected = {node for topic, nodes in subscribers if topic == pub.resolved_name for node in nodes}
    deadline = time.monotonic() + timeout
    while True:
        waiting = [node for node in expected if not pub.reaches(node)]
        if not waiting or time.monotonic() >= deadline:
            break
        time.sleep(0.01)
    if not waiting:
        return
    _log.info("micros_rt mqtt: ROS topic '%s': subscriber(s) %s not connected %.0f s after advertising; "
              "publishing anyway (they miss what comes before they connect)", pub.resolved_name,
              ", ".join(sorted(waiting)), timeout)


def _message_class(t: codec.RosMsgType) -> Type[genpy.Message]:
    """The installed class when its md5 matches the announcement, else one built from the definition."""
    cls = roslib.message.get_message_class(t.name)
    if cls is not None and cls._md5sum == t.md5:
        return cls  # type: ignore[no-any-return]
    built = genpy.dynamic.generate_dynamic(t.name, t.definition)[t.name]
    if built._md5sum != t.md5:
        raise ValueError(f"the definition's md5 is {built._md5sum}, the announcement says {t.md5}")
    return built  # type: ignore[no-any-return]


class MqttBridge:
    """The bridge; ``micros_rt.init_node`` must have been called. ``close()`` (or ``with``) stops it."""

    def __init__(self, params: MqttParams, *, on_fatal: Optional[Callable[[str], None]] = None) -> None:
        self.params = params
        self.nh = micros_rt.NodeHandle()
        self.problems = _Problems()
        self._closed = threading.Event()
        self.generations = PeerGenerations(
            fixed=params.wire if params.wire_set else None, default=params.wire,
            fixed_topics={p.mqtt_topic: p.wire for p in params.ros2mqtt if p.wire is not None},
            written=[p.mqtt_topic for p in params.ros2mqtt if not (p.primitive or p.json)])
        self.connection = MqttConnection(params, on_fatal=on_fatal, on_connection_change=self._connection_changed,
                                         on_live=self._on_live)
        self.ros2mqtt = [_Ros2Mqtt(self, p) for p in params.ros2mqtt]
        self.mqtt2ros = [_Mqtt2Ros(self, p) for p in params.mqtt2ros]
        # the peers' generations are read from their announcements: all of them, with one subscription (it
        # also feeds the mqtt2ros topics' announcements), when some topic written follows the peers
        self.follows_peers = any(r.framed and r.p.wire is None for r in self.ros2mqtt) and \
            self.generations.follows_peers
        self._type_readers: Dict[str, _Mqtt2Ros] = {}
        self._scan_topic = f"micros_rt/scan/{uuid.uuid4().hex}"
        self._scanned = threading.Event()     # the broker's retained announcements have arrived (this connection)
        self._scan_lock = threading.Lock()
        self._scan_started = 0.0              # monotonic time of the scan under way (0: none)
        self._watching = False                # mqtt_client/ros_msg_type/# subscribed (a scan, or a topic holding)
        self._scan_now = threading.Event()
        self._live_since: Optional[float] = None
        self.scans = 0
        for r in self.ros2mqtt:
            kind = "primitive " if r.p.primitive else "JSON " if r.p.json else ""
            _log.info("Bridging %sROS topic '%s' to MQTT topic '%s'", kind, r.p.ros_topic, r.p.mqtt_topic)
        for m in self.mqtt2ros:
            kind = "primitive " if m.p.primitive else "JSON " if m.p.json else ""
            _log.info("Bridging MQTT topic '%s' to %sROS topic '%s'", m.p.mqtt_topic, kind, m.p.ros_topic)
            self.connection.subscribe(m.p.mqtt_topic, m.p.qos, m.feed_data)
            if not (m.p.primitive or m.p.json):
                # its type topic until a type is taken: then scans show a change (a peer repeats its
                # announcement with every message; subscribed, each would cost paho's decoding of a message)
                self._type_readers[codec.ROS_MSG_TYPE_PREFIX + m.p.mqtt_topic] = m
                self.connection.subscribe(codec.ROS_MSG_TYPE_PREFIX + m.p.mqtt_topic, m.p.qos, self._on_announcement)
        self._announcement_qos = max([m.p.qos for m in self._type_readers.values()], default=0)
        self.scanning = self.follows_peers or bool(self._type_readers)
        if self.scanning:
            self.connection.subscribe(self._scan_topic, 0, self._on_scan)
        if self.follows_peers:
            held = [r.p.mqtt_topic for r in self.ros2mqtt if r.holding]
            _log.info("micros_rt mqtt: writing each MQTT topic in the mqtt_client generation its peers announce "
                      "on the broker (bridge/mqtt_client_version fixes it); reading 1.x and 2.x. Until a peer has "
                      "announced a type, a topic's messages wait, for %g s at most, then %s is written. A 1.x "
                      "mqtt_client that only reads (%s) announces nothing: give this bridge mqtt_client_version: 1 "
                      "(bridge-wide or on the topic), else it misreads %s payloads", PEER_HOLD, params.wire.label,
                      ", ".join(f"'{t}'" for t in held) or "no topic here", params.wire.label)
        else:
            _log.info("micros_rt mqtt: writing mqtt_client %s payloads and type announcements "
                      "(bridge/mqtt_client_version: %d); reading 1.x and 2.x", params.wire.label, int(params.wire))
        self._service_lock = threading.Lock()
        self._read_generations: Dict[str, codec.WireGeneration] = {}   # mqtt2ros topic -> its peer's generation
        self._service_class = is_connected_service_class(params.wire, package=self._is_connected_package())
        self._service = rospy.Service("~is_connected", self._service_class, self._is_connected)
        self._resolver = threading.Thread(target=self._resolve_loop, name="micros_rt mqtt types", daemon=True)
        self._scanner = threading.Thread(target=self._scan_loop, name="micros_rt mqtt scans", daemon=True)

    def start(self) -> None:
        """Connect to the broker (in the background) and start subscribing ROS topics as they appear."""
        self.connection.start()
        self._resolver.start()
        if self.scanning:
            self._scanner.start()

    def _is_connected_package(self) -> str:
        """The package of ``~is_connected``'s type: an installed one (what rosservice here can load), the peers'
        generation's first when both are; none installed, the peers' generation's (``mqtt_client`` for 1.x,
        ``mqtt_client_interfaces`` for 2.x), so that a caller with their mqtt_client can load it. The
        generation: the setting, else the one every peer on the broker announces, else 2.x."""
        wire = self.params.wire
        if not self.params.wire_set:
            seen = set(self.generations.peers().values()) | set(self._read_generations.values())
            if len(seen) == 1:
                wire = seen.pop()
        return installed_is_connected_package(wire) or IS_CONNECTED_PACKAGE[wire]

    def note_read_generation(self, topic: str, wire: codec.WireGeneration) -> None:
        """A peer announced ``topic``, read here, in ``wire``: it may change ``~is_connected``'s type."""
        if self._read_generations.get(topic) is not wire:
            self._read_generations[topic] = wire
            self._retype_is_connected()

    def _retype_is_connected(self) -> None:
        """Advertise ``~is_connected`` anew when the peers' generation changes its package (on a thread of its
        own: registering with the master must not hold paho's thread or a topic's worker)."""
        if self.params.wire_set or self._closed.is_set():
            return
        package = self._is_connected_package()
        if self._service_class._type == f"{package}/IsConnected":
            return

        def retype() -> None:
            with self._service_lock:
                if self._closed.is_set() or self._service_class._type == f"{package}/IsConnected":
                    return
                before = self._service_class._type
                self._service.shutdown()
                self._service_class = is_connected_service_class(package=package)
                self._service = rospy.Service("~is_connected", self._service_class, self._is_connected)
                _log.info("micros_rt mqtt: ~is_connected is now a %s (was %s): the peers on the broker speak "
                          "mqtt_client %s", self._service_class._type, before,
                          "1.x" if package == IS_CONNECTED_PACKAGE[codec.WireGeneration.V1] else "2.x")
        threading.Thread(target=retype, name="micros_rt mqtt is_connected", daemon=True).start()

    def _is_connected(self, request: Any) -> Any:
        return self._service_class._response_class(connected=self.connection.is_connected)

    def _connection_changed(self, connected: bool) -> None:
        if connected:
            self._scanned.clear()
            with self._scan_lock:
                self._scan_started = 0.0
            for r in self.ros2mqtt:
                r.announced = None     # the retained announcement may be gone with a restarted broker

    def _on_live(self) -> None:
        """Sending is enabled (after each connect): look at the broker's announcements (a scan), then announce;
        with no peers to follow, announce now."""
        if self._live_since is None:
            self._live_since = time.monotonic()
        if self.scanning:
            self._start_scan()
        if not self.follows_peers:
            self._announce_all()

    # -- the broker's type announcements: scans, and a watch while a topic holds its messages

    def _holding(self) -> bool:
        return self.follows_peers and any(r.holding for r in self.ros2mqtt)

    def _start_scan(self) -> None:
        """Subscribe ``mqtt_client/ros_msg_type/#`` (the broker sends its retained announcements), then publish a
        marker to this bridge's scan topic: when it comes back, they have all arrived (:meth:`_on_scan`)."""
        now = time.monotonic()
        with self._scan_lock:
            if self._scan_started and now - self._scan_started < SCAN_TIMEOUT:
                return
            self._scan_started = now
            subscribe, self._watching = not self._watching, True
        if subscribe:
            self.connection.subscribe(ANNOUNCEMENTS, self._announcement_qos, self._on_announcement)
        self.connection.publish(self._scan_topic, b"", qos=0)

    def _on_scan(self, topic: str, payload: bytes, properties: Any = None) -> None:
        """The end of a scan: unsubscribe the announcements again, unless a topic still holds its messages
        for a peer's generation (then every announcement counts at once)."""
        with self._scan_lock:
            self._scan_started = 0.0
            unsubscribe = self._watching and not self._holding()
            if unsubscribe:
                self._watching = False
        if unsubscribe:
            self.connection.unsubscribe(ANNOUNCEMENTS)
        self.scans += 1
        if not self._scanned.is_set():
            self._scanned.set()
            if self.follows_peers:
                self._announce_all()

    def end_watch(self) -> None:
        """No topic holds its messages any more: stop receiving every announcement (unless a scan is under way,
        which ends it)."""
        with self._scan_lock:
            unsubscribe = self._watching and not self._scan_started and not self._holding()
            if unsubscribe:
                self._watching = False
        if unsubscribe:
            self.connection.unsubscribe(ANNOUNCEMENTS)

    def request_scan(self) -> None:
        """Look at the broker's announcements now (a payload that did not decode: its type may have changed)."""
        self._scan_now.set()

    def _scan_loop(self) -> None:
        while not self._closed.is_set():
            self._scan_now.wait(SCAN_INTERVAL)
            self._scan_now.clear()
            if self._closed.is_set():
                return
            now = time.monotonic()
            for r in self.ros2mqtt:
                r.check_hold(now, self._live_since)
            if self.connection.is_live:
                self._start_scan()

    def _announce_all(self) -> None:
        for r in self.ros2mqtt:
            r.redecide()
            r.announce(force=True)

    def _on_announcement(self, topic: str, payload: bytes, properties: Any = None) -> None:
        """Every ``mqtt_client/ros_msg_type/...`` message (paho's thread): a peer's generation, and the
        announcement of an mqtt2ros topic."""
        reader = self._type_readers.get(topic)
        if reader is not None:
            reader.feed_type(topic, payload)
        if self.generations.observe(topic, payload):
            for r in self.ros2mqtt:
                if r.framed:
                    r.redecide()
            self._retype_is_connected()

    def _resolve_loop(self) -> None:
        while not self._closed.wait(RESOLVE_INTERVAL):
            waiting = [r for r in self.ros2mqtt if r.subscriber is None and r.raw_subscriber is None]
            if not waiting:
                return
            try:
                published = dict(rospy.get_published_topics())
            except Exception as exc:  # master away: try again
                _log.debug("micros_rt mqtt: cannot ask the master for topic types: %s", exc)
                continue
            for r in waiting:
                name = rospy.resolve_name(r.p.ros_topic)
                type_name = published.get(name)
                if type_name is None:
                    continue
                cls = roslib.message.get_message_class(type_name)
                if cls is None or r.framed:   # framed: bytes over TCPROS, as mqtt_client's ShapeShifter
                    r.attach_raw(type_name, installed=cls is not None)
                else:
                    r.attach(cls)

    def counters(self) -> Dict[str, Any]:
        """Counts: messages sent and delivered, each kind of bad input, the connection's counters."""
        out: Dict[str, Any] = {"sent": {r.p.ros_topic: r.sent for r in self.ros2mqtt},
                               "delivered": {m.p.ros_topic: m.delivered for m in self.mqtt2ros},
                               "retyped": {m.p.ros_topic: m.retyped for m in self.mqtt2ros if m.retyped},
                               "held": {r.p.mqtt_topic: r.held for r in self.ros2mqtt if r.held},
                               "scans": self.scans,
                               "bad_input": dict(self.problems.counts)}
        out.update(vars(self.connection.counters()))
        return out

    def close(self) -> None:
        """Stop the bridge (disconnects cleanly, so no last will); harmless twice."""
        if self._closed.is_set():
            return
        self._closed.set()
        self.connection.close()
        with self._service_lock:
            self._service.shutdown()
        for r in self.ros2mqtt:
            for sub in (r.subscriber, r.raw_subscriber):
                if sub is not None:
                    sub.unregister()
        for m in self.mqtt2ros:
            m.worker.close()
            for pub in (m.publisher, m.latency_pub):
                if pub is not None:
                    pub.unregister()
        _log.info("micros_rt mqtt: counters: %s", self.counters())

    def __enter__(self) -> "MqttBridge":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

