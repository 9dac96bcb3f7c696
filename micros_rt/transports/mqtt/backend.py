"""MQTT as a back end of any micros_rt topic, chosen in the YAML profile (AimRT's per-topic back ends).

A profile's ``mqtt`` section names the broker (mqtt_client's ``broker``/``client`` parameters) and the
topics that also travel over MQTT, by exact name, glob or ``^...$`` regular expression::

    mqtt:
      broker: {host: 127.0.0.1, port: 1883}
      client: {id: robot1}
      topics:
        /chatter: {mqtt_topic: robot1/chatter, codec: json}
        "^/fleet/.*$": {qos: 2}
        "/camera/*": {direction: out}

A publisher of a matching topic mirrors every message to the broker; a subscriber is fed from it, through
the same delivery path as its TCPROS links (time filter, deadline, latency statistics, ``statistics()``),
with ``transport`` ``MQTT`` in the connection header and in ``connection_transports()``. Messages carry
their publisher's graph and node in an MQTT 5 user property: a subscriber drops MQTT copies of messages
from its own ROS graph, which reach it over DDS/TCPROS, so each message is delivered once.

QoS: best effort -> MQTT QoS 0, reliable -> 1 (a rule's ``qos`` may choose 2); ``latch`` -> retained;
``msg_valid_period`` -> MQTT 5 message expiry (whole seconds, rounded up); ``transport_priority`` -> IP
TOS on the client's socket (the process's highest). Codecs: ``ros1`` (mqtt_client's framing, with its
type announcement: mqtt_client bridges read it), ``json``, ``primitive``. ``ros1`` writes the generation of
the section's ``mqtt_client_version`` (2, the default, or 1) and reads both; a payload that arrives before
its topic's type announcement is held (up to :data:`PENDING_LIMIT`) until the announcement says its form.
"""

from __future__ import annotations

import atexit
import dataclasses
import io
import math
import re
import collections
import threading
import weakref
from typing import Any, Callable, Deque, Dict, List, Optional, Pattern, Tuple

import genpy

from ...log import nonblocking_logger
from ..base import EndpointSpec
from ...exceptions import ProfileError, TransportError
from ...ratelimit import RateLimitedLog
from ...qos.topic_rules import TopicPattern, best_match
from ...qos import AdvertiseQoSOptions, SubscribeQoSOptions, TransportPriority, priority_socket_priority, priority_tos
from . import codec
from .client import MqttConnection
from .params import ConnectionParams, ParamsError, ParamsReader, parse_connection, parse_wire

__all__ = ["MqttBackend", "MqttRule", "MqttSettings", "MqttTopicReader", "MqttTopicWriter", "parse_mqtt_section",
           "process_backend", "close_process_backend", "SOURCE_PROPERTY"]

_log = nonblocking_logger("rosout.micros_rt.mqtt")
_problems = RateLimitedLog(_log, interval=30.0)

#: MQTT 5 user property naming the publishing graph and node: ``<graph>|<node>``.
SOURCE_PROPERTY = "micros_rt"
CODECS = ("ros1", "json", "primitive")
#: How long the first topic with an MQTT rule waits for the broker (seconds).
CONNECT_WAIT = 5.0
DIRECTIONS = ("both", "out", "in")
#: ``ros1`` payloads held per topic while its type announcement (which says their form) has not come.
PENDING_LIMIT = 100


@dataclasses.dataclass(frozen=True)
class MqttRule:
    """One ``mqtt.topics`` entry."""

    key: str
    order: int
    mqtt_topic: str = "{ros_topic}"
    direction: str = "both"
    qos: Optional[int] = None
    retained: Optional[bool] = None
    codec: str = "ros1"
    regex: Optional[Pattern[str]] = None

    @property
    def pattern(self) -> TopicPattern:
        return TopicPattern(self.key, self.regex)

    def matches(self, topic: str) -> bool:
        return self.pattern.matches(topic)

    @property
    def exact(self) -> bool:
        return self.pattern.exact

    def mqtt_name(self, ros_topic: str) -> str:
        """The MQTT topic for a ROS topic (``{ros_topic}``: the ROS name without its leading slash)."""
        return self.mqtt_topic.replace("{ros_topic}", ros_topic.lstrip("/"))


@dataclasses.dataclass(frozen=True)
class MqttSettings:
    """A profile's ``mqtt`` section."""

    params: ConnectionParams
    rules: Tuple[MqttRule, ...]
    source: str
    #: the mqtt_client generation ``ros1`` topics are written in (``mqtt_client_version``)
    wire: codec.WireGeneration = codec.WireGeneration.V2

    def rule_for(self, topic: str, direction: str) -> Optional[MqttRule]:
        """The rule for ``topic`` going ``out`` or ``in``: an exact name beats a pattern, the longest pattern
        wins, then the first in the file."""
        return best_match(((r.pattern, r) for r in self.rules if r.direction in ("both", direction)), topic)


def parse_mqtt_section(data: Any, *, source: str) -> MqttSettings:
    """Validate a profile's ``mqtt`` section; :class:`micros_rt.ProfileError` naming the key."""
    r = ParamsReader(f"{source}: mqtt")
    try:
        if not isinstance(data, dict):
            raise ParamsError(f"{source}: mqtt: expected a mapping with 'broker', 'client' and 'topics'")
        r.check_keys(data, ("broker", "client", "topics", "mqtt_client_version"), "")
        broker, client = parse_connection(r, data)
        wire = parse_wire(r, data, "mqtt_client_version")
        topics = data.get("topics") or {}         # none: only services over MQTT
        if not isinstance(topics, dict):
            raise ParamsError(f"{source}: mqtt: 'topics' must map topic names/patterns to MQTT options")
        rules = tuple(_rule(r, str(key), value or {}, k) for k, (key, value) in enumerate(topics.items()))
    except ParamsError as exc:
        raise ProfileError(str(exc)) from None
    return MqttSettings(ConnectionParams(broker, client), rules, source, wire)


def _rule(r: ParamsReader, key: str, value: Any, order: int) -> MqttRule:
    name = f"topics/{key}"
    if not isinstance(value, dict):
        raise r.fail(name, f"must be a mapping of MQTT options, got {value!r}")
    r.check_keys(value, ("mqtt_topic", "direction", "qos", "retained", "codec"), name)
    try:
        regex = TopicPattern.parse(key).regex
    except re.error as exc:
        raise r.fail(name, f"is not a valid regular expression: {exc}") from None
    if regex is None and not key.startswith("/"):
        raise r.fail(name, "must be a resolved ROS name ('/...'), a glob, or a '^...$' regular expression")
    rule = MqttRule(
        key=key, order=order, regex=regex,
        mqtt_topic=r.get(value, "mqtt_topic", f"{name}/mqtt_topic", str, "{ros_topic}", warn=False),
        direction=r.get(value, "direction", f"{name}/direction", str, "both", warn=False),
        qos=r.get(value, "qos", f"{name}/qos", int, None, warn=False, lo=0, hi=2),
        retained=r.get(value, "retained", f"{name}/retained", bool, None, warn=False),
        codec=r.get(value, "codec", f"{name}/codec", str, "ros1", warn=False),
    )
    if rule.direction not in DIRECTIONS:
        raise r.fail(f"{name}/direction", f"is {rule.direction!r}; one of {', '.join(DIRECTIONS)}")
    if rule.codec not in CODECS:
        raise r.fail(f"{name}/codec", f"is {rule.codec!r}; one of {', '.join(CODECS)}")
    if any(c in rule.mqtt_topic for c in "+#") or not rule.mqtt_topic:
        raise r.fail(f"{name}/mqtt_topic", f"is {rule.mqtt_topic!r}: a non-empty MQTT topic without wildcards")
    return rule


class MqttBackend:
    """The process's MQTT connection (MQTT 5) and its topic writers and readers."""

    def __init__(self, settings: MqttSettings, *, graph: str, node: str) -> None:
        self.settings = settings
        self.graph, self.node = graph, node
        self.source = f"{graph}|{node}"
        self.generation = 0          # connections so far: type announcements are re-sent on each
        self._priorities: List[TransportPriority] = []
        self._lock = threading.Lock()
        self._writers: "weakref.WeakSet[MqttTopicWriter]" = weakref.WeakSet()
        self.connection = MqttConnection(settings.params, mqtt5=True, on_connection_change=self._changed,
                                         on_live=self._on_live)
        self.connection.start()
        # the first messages of a process's topics must not be dropped for a connection still being made
        if not self.connection.wait_connected(CONNECT_WAIT):
            _log.warning("micros_rt: MQTT broker %s not reached within %.0f s; messages are dropped (or buffered "
                         "with client/id and client/buffer/size) until it is", self.connection.uri, CONNECT_WAIT)

    def _changed(self, connected: bool) -> None:
        if connected:
            self.generation += 1

    def _on_live(self) -> None:
        """Sending is enabled after a connect: every writer's type announcement goes (again) to the broker,
        which may have lost its retained copy (a restarted broker) or never got it (sent too early)."""
        with self._lock:
            writers = list(self._writers)
        for w in writers:
            w.announce()

    def open_writer(self, spec: EndpointSpec, options: AdvertiseQoSOptions) -> "Optional[MqttTopicWriter]":
        rule = self.settings.rule_for(spec.topic, "out")
        if rule is None:
            return None
        with self._lock:
            self._priorities.append(options.transport_priority)
            top = max(self._priorities, key=int)
        if top != TransportPriority.NORMAL:
            self.connection.set_tos(priority_tos(top), priority_socket_priority(top))
        writer = MqttTopicWriter(self, rule, spec, options)
        with self._lock:
            self._writers.add(writer)
        return writer

    def open_feed(self, spec: EndpointSpec, options: Optional[SubscribeQoSOptions],
                  deliver: Callable[[Any], None]) -> "Optional[MqttTopicReader]":
        rule = self.settings.rule_for(spec.topic, "in")
        if rule is None:
            return None
        return MqttTopicReader(self, rule, spec, options, deliver)

    def close(self) -> None:
        self.connection.close()


class MqttTopicWriter:
    """Mirrors a publication's messages to its MQTT topic."""

    protocol = "MQTT"

    def __init__(self, backend: MqttBackend, rule: MqttRule, spec: EndpointSpec,
                 options: AdvertiseQoSOptions) -> None:
        self.backend, self.rule, self.spec = backend, rule, spec
        self.mqtt_topic = rule.mqtt_name(spec.topic)
        self.qos = rule.qos if rule.qos is not None else (0 if options.using_best_effort_protocol else 1)
        self.retain = rule.retained if rule.retained is not None else spec.latch
        period = options.msg_valid_period
        self.expiry = int(math.ceil(period)) if math.isfinite(period) and period > 0 else None
        self._announced = -1              # the connection (backend.generation) that took the announcement
        self._msg_class: Any = None       # the type announced (ros1 codec), once known
        self._announce_lock = threading.Lock()
        self.sent = 0
        self.closed = False
        _log.info("micros_rt: topic %s is mirrored to MQTT topic '%s' (%s, QoS %d%s)", spec.topic, self.mqtt_topic,
                  rule.codec, self.qos, ", retained" if self.retain else "")

    def _properties(self) -> Any:
        from paho.mqtt.packettypes import PacketTypes
        from paho.mqtt.properties import Properties

        props = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
        props.UserProperty = [(SOURCE_PROPERTY, self.backend.source)]
        if self.expiry is not None:
            props.MessageExpiryInterval = self.expiry
        return props

    def prepare(self, msg: genpy.Message) -> Tuple[bytes, Any]:
        """Encode with the rule's codec (raises on a bad value, before the publication sends anything)."""
        if self.rule.codec == "json":
            return codec.msg_to_json(msg).encode("utf-8"), None
        if self.rule.codec == "primitive":
            return codec.msg_to_text(msg).encode("utf-8"), None
        buf = io.BytesIO()
        msg.serialize(buf)
        return codec.encode_ros_payload(buf.getvalue(), wire=self.backend.settings.wire), type(msg)

    def send(self, prepared: Tuple[bytes, Any]) -> None:
        """Publish what :meth:`prepare` made (buffered on disk while disconnected, if configured)."""
        if self.closed:
            raise TransportError(f"topic {self.spec.topic}: its MQTT writer is closed (the publication was "
                                 f"unregistered); nothing was sent to '{self.mqtt_topic}'")
        payload, msg_class = prepared
        conn = self.backend.connection
        if msg_class is not None and (self._announced != self.backend.generation or msg_class is not self._msg_class):
            self._msg_class = msg_class
            self.announce()
        try:
            if conn.publish(self.mqtt_topic, payload, qos=self.qos, retain=self.retain, properties=self._properties()):
                self.sent += 1
        except ValueError as exc:
            _problems.warning((self.spec.topic, "too_large"), f"topic {self.spec.topic}: a {len(payload)}-byte "
                              f"message cannot go to MQTT topic '{self.mqtt_topic}': {exc}")

    def announce(self) -> None:
        """mqtt_client's type announcement (retained), once per connection: marked sent only when the
        connection took it (sent, or kept in the disk buffer); else the next message, or the connection
        coming up, sends it."""
        with self._announce_lock:
            msg_class, generation = self._msg_class, self.backend.generation
            if msg_class is None or self.closed or not self.backend.connection.can_send:
                return
            raw = codec.encode_msg_type(codec.RosMsgType.of(msg_class).for_wire(self.backend.settings.wire,
                                                                               stamped=False))
            if self.backend.connection.publish(codec.ROS_MSG_TYPE_PREFIX + self.mqtt_topic, raw, qos=self.qos,
                                               retain=True):
                self._announced = generation

    def close(self) -> None:
        """Refuse further sends; the connection is the process's, it stays."""
        self.closed = True


class MqttTopicReader:
    """Feeds a subscription from its MQTT topic (messages of other graphs and of non-ROS clients)."""

    protocol = "MQTT"

    def __init__(self, backend: MqttBackend, rule: MqttRule, spec: EndpointSpec,
                 options: Optional[SubscribeQoSOptions], deliver: Callable[[Any], None]) -> None:
        self.backend, self.rule, self.spec = backend, rule, spec
        self.mqtt_topic = rule.mqtt_name(spec.topic)
        best_effort = options is not None and options.using_best_effort_protocol
        self.qos = rule.qos if rule.qos is not None else (0 if best_effort else 1)
        self._deliver = deliver
        self._lock = threading.Lock()
        self.announced_md5 = ""
        self.announced = False               # the payload form is known (from the type announcement)
        self.stamped: Optional[bool] = None  # announced stamped field; None: 1.x (flag byte)
        self.pending: Deque[Tuple[str, bytes, Any]] = collections.deque()
        self.delivered = self.same_graph = self.malformed = self.held_dropped = 0
        params = backend.settings.params.broker
        self.uri = f"mqtt://{params.host}:{params.port}/{self.mqtt_topic}"
        backend.connection.subscribe(self.mqtt_topic, self.qos, self._on_message)
        if rule.codec == "ros1":
            backend.connection.subscribe(codec.ROS_MSG_TYPE_PREFIX + self.mqtt_topic, self.qos, self._on_type)
        _log.info("micros_rt: topic %s is fed from MQTT topic '%s' (%s, QoS %d)", spec.topic, self.mqtt_topic,
                  rule.codec, self.qos)

    def _on_type(self, topic: str, payload: bytes, properties: Any) -> None:
        try:
            announced = codec.decode_msg_type(payload)
        except codec.CodecError as exc:
            self._bad("bad_type", f"its type announcement does not decode: {exc}")
            return
        with self._lock:
            self.announced_md5, self.stamped, self.announced = announced.md5, announced.stamped, True
            pending, self.pending = list(self.pending), collections.deque()
        for held in pending:
            self._on_message(*held)

    def _bad(self, kind: str, text: str) -> None:
        self.malformed += 1
        _problems.warning((self.mqtt_topic, kind), f"topic {self.spec.topic}: MQTT topic '{self.mqtt_topic}': "
                                                   f"{text}; dropped (further ones are counted)")

    def _on_message(self, topic: str, payload: bytes, properties: Any) -> None:
        source = dict(getattr(properties, "UserProperty", None) or []).get(SOURCE_PROPERTY, "")
        graph, _, node = source.partition("|")
        if graph == self.backend.graph:
            self.same_graph += 1          # it reaches this subscriber over DDS/TCPROS
            return
        cls = self.spec.data_class
        if self.rule.codec == "ros1":
            with self._lock:
                if not self.announced:     # its form (flag byte, or 2.x stamped or not) is not known yet
                    if len(self.pending) >= PENDING_LIMIT:
                        self.pending.popleft()
                        self.held_dropped += 1
                        _problems.warning((self.mqtt_topic, "no_type"), f"topic {self.spec.topic}: MQTT topic "
                                          f"'{self.mqtt_topic}': no type announced yet on '{codec.ROS_MSG_TYPE_PREFIX}"
                                          f"{self.mqtt_topic}'; holding the newest {PENDING_LIMIT} messages")
                    self.pending.append((topic, payload, properties))
                    return
                stamped = self.stamped
        try:
            if self.rule.codec == "json":
                msg = codec.json_to_msg(payload.decode("utf-8"), cls)
            elif self.rule.codec == "primitive":
                msg = codec.text_to_msg(payload.decode("utf-8"), cls)
            else:
                if self.announced_md5 and self.announced_md5 != cls._md5sum:
                    self._bad("type_mismatch", f"announced md5 {self.announced_md5} is not {cls._type}'s "
                                               f"{cls._md5sum}")
                    return
                _, body = codec.decode_ros_payload(payload, stamped=stamped)
                msg = cls()
                msg.deserialize(bytes(body))
        except Exception as exc:  # codec errors, genpy's struct.error/DeserializationError, UnicodeDecodeError
            self._bad("malformed", f"a {len(payload)}-byte payload does not decode as {cls._type} "
                                   f"({self.rule.codec}): {exc or type(exc).__name__}")
            return
        msg._connection_header = {"callerid": node or f"mqtt:{self.mqtt_topic}", "topic": self.spec.topic,
                                  "type": cls._type, "md5sum": cls._md5sum, "transport": "MQTT"}
        self.delivered += 1
        self._deliver(msg)

    def transports(self) -> Dict[str, str]:
        """For ``connection_transports()``: the MQTT link."""
        return {self.uri: "MQTT"}

    def close(self) -> None:
        self.backend.connection.unsubscribe(self.mqtt_topic)
        if self.rule.codec == "ros1":
            self.backend.connection.unsubscribe(codec.ROS_MSG_TYPE_PREFIX + self.mqtt_topic)


_process_lock = threading.Lock()
_process: Optional[Tuple[Any, MqttBackend]] = None


def process_backend(profile: Any, *, graph: str, node: str) -> MqttBackend:
    """The process's back end for ``profile`` (created at the first topic that needs it)."""
    global _process
    with _process_lock:
        if _process is None or _process[0] is not profile:
            if _process is not None:
                _process[1].close()
            settings = parse_mqtt_section(profile.mqtt, source=str(getattr(profile, "source", "profile")))
            backend = MqttBackend(settings, graph=graph, node=node)
            _process = (profile, backend)
            atexit.register(backend.close)  # a process that never shuts its node down (close is harmless twice)
        return _process[1]


def close_process_backend() -> None:
    """Close the process's back end (the node shuts down); the next topic with an MQTT rule makes a new one."""
    global _process
    with _process_lock:
        current, _process = _process, None
    if current is not None:
        current[1].close()
