"""The MQTT connection: paho-mqtt 2.x with TLS, authentication, last will, keep-alive, reconnection with
back-off, subscriptions restored on reconnect, and an ordered disk buffer while the broker is away.

Ordering across an outage. paho keeps QoS 1/2 messages it sent but has no acknowledgement for and sends
them again right after the broker's CONNACK, *after* ``on_connect`` returns. Messages buffered on disk
during the outage are newer, so they are flushed by a thread of this class a moment after the
connection is up (never from ``on_connect``), and new messages wait in the buffer until the flush is
done: the broker sees every message in the order it was published.

>>> conn = MqttConnection(params)                            # doctest: +SKIP
>>> conn.subscribe("pingpong/primitive", 1, on_message)      # doctest: +SKIP
>>> conn.start(); conn.publish("pingpong/ros", b"\\x00...", qos=1)   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
import ssl
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTErrorCode
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode

from ...log import nonblocking_logger
from ...ratelimit import RateLimitedLog
from .params import ConnectionParams, resolve_path
from ...exceptions import MicrosRtError
from ..marking import mark_socket_tos

__all__ = ["ConnectionCounters", "DiskBuffer", "MqttConfigError", "MqttConnection", "MessageHandler",
           "properties_from_dict", "properties_to_dict"]

_log = nonblocking_logger("rosout.micros_rt.mqtt")
_too_large = RateLimitedLog(_log, interval=30.0)

#: MQTT PUBLISH header bytes besides topic and payload (fixed header, lengths, packet id, properties).
PUBLISH_OVERHEAD = 16

#: ``handler(topic, payload, properties)``, called on paho's network thread (properties: MQTT 5 only).
MessageHandler = Callable[[str, bytes, Optional[Properties]], None]

#: Reconnect back-off (seconds): paho doubles the delay between these bounds.
RECONNECT_MIN_DELAY = 1
RECONNECT_MAX_DELAY = 8


class MqttConfigError(MicrosRtError, ValueError):
    """A connection setting that cannot work (missing or unreadable certificate, bad key password...)."""


@dataclasses.dataclass
class ConnectionCounters:
    """What happened on the connection (read with :meth:`MqttConnection.counters`)."""

    published: int = 0
    buffered: int = 0
    flushed: int = 0
    dropped_disconnected: int = 0
    dropped_buffer_full: int = 0
    dropped_expired: int = 0
    dropped_too_large: int = 0
    received: int = 0
    connects: int = 0
    disconnects: int = 0


class DiskBuffer:
    """Messages kept in order on disk while the broker is unreachable: one file per message,
    ``<directory>/<seq:012d>.mqtt``, a JSON header line then the payload. Files left by an earlier run of
    the same client id are sent first. At most ``size`` messages; ``max_age`` > 0 drops older ones."""

    def __init__(self, directory: str, size: int, *, max_age: float = 0.0) -> None:
        self.directory = Path(directory)
        self.size = size
        self.max_age = max_age
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise MqttConfigError(f"cannot create the buffer directory {str(self.directory)!r} "
                                  f"(client/buffer/directory): {exc.strerror or exc}") from exc
        self._files: List[Path] = sorted(self.directory.glob("*.mqtt"))
        self._next = int(self._files[-1].stem) + 1 if self._files else 0

    def __len__(self) -> int:
        return len(self._files)

    def put(self, topic: str, payload: bytes, qos: int, retain: bool,
            properties: Optional[Dict[str, Any]] = None) -> bool:
        """Store one message (``properties``: MQTT 5 ones as :func:`properties_to_dict` gives them);
        False when the buffer is full (the message is not stored)."""
        if len(self._files) >= self.size:
            return False
        header = json.dumps({"topic": topic, "qos": qos, "retain": retain, "time": time.time(),
                             "properties": properties})
        path = self.directory / f"{self._next:012d}.mqtt"
        tmp = path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            f.write(header.encode("utf-8") + b"\n" + payload)
        os.replace(tmp, path)
        self._next += 1
        self._files.append(path)
        return True

    def pop(self) -> Optional[Tuple[str, bytes, int, bool, float, Optional[Dict[str, Any]]]]:
        """The oldest message (topic, payload, qos, retain, age in seconds, properties), removed; None when
        empty."""
        while self._files:
            path = self._files.pop(0)
            try:
                raw = path.read_bytes()
                path.unlink()
                head, _, payload = raw.partition(b"\n")
                meta = json.loads(head)
                return (str(meta["topic"]), payload, int(meta["qos"]), bool(meta["retain"]),
                        time.time() - float(meta["time"]), meta.get("properties"))
            except (OSError, ValueError, KeyError) as exc:
                _log.warning("micros_rt mqtt: skipping unreadable buffered message %s: %s", path, exc)
        return None


class _PahoClient(paho.Client):
    """paho's client, remembering why the last connection attempt failed (paho's loop swallows it)."""

    last_error: Optional[OSError] = None

    def reconnect(self) -> MQTTErrorCode:
        try:
            return super().reconnect()
        except OSError as exc:
            self.last_error = exc
            raise


def properties_to_dict(props: Optional[Properties]) -> Optional[Dict[str, Any]]:
    """The MQTT 5 publish properties micros_rt uses (user properties, message expiry), as JSON values."""
    if props is None:
        return None
    return {"user": [list(p) for p in getattr(props, "UserProperty", [])],
            "expiry": getattr(props, "MessageExpiryInterval", None)}


def properties_from_dict(data: Optional[Dict[str, Any]], *, age: float = 0.0) -> Optional[Properties]:
    """Inverse of :func:`properties_to_dict`; the expiry shortened by ``age`` seconds spent in a buffer."""
    if not data:
        return None
    props = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
    if data.get("user"):
        props.UserProperty = [tuple(p) for p in data["user"]]
    if data.get("expiry") is not None:
        props.MessageExpiryInterval = max(1, int(data["expiry"] - age))
    return props


def _reason_text(rc: Any) -> str:
    if isinstance(rc, ReasonCode):
        return str(rc.getName())
    if isinstance(rc, MQTTErrorCode):
        return paho.error_string(rc)
    return str(rc)


class MqttConnection:
    """One MQTT client connection configured from mqtt_client's parameters.

    ``start()`` connects in the background and never raises for an unreachable broker: it is retried with
    back-off (1 s doubling to 8 s) and each failure is logged. ``on_connection_change(True)`` is called at
    the broker's CONNACK, when sending is not enabled yet (the disk buffer is flushed first);
    ``on_live()`` once sending is enabled, on the flush thread: what must be on the broker after every
    connect (mqtt_client's retained type announcements) is published from there. ``fatal`` is set (and
    ``on_fatal`` called) when retrying cannot help: the broker's certificate fails verification against the
    configured CA, or the broker refuses the credentials.
    """

    def __init__(self, params: ConnectionParams, *, mqtt5: bool = False, on_fatal: Optional[Callable[[str], None]] = None,
                 on_connection_change: Optional[Callable[[bool], None]] = None,
                 on_live: Optional[Callable[[], None]] = None) -> None:
        self.params = params
        self.uri = f"{'ssl' if params.broker.tls_enabled else 'tcp'}://{params.broker.host}:{params.broker.port}"
        self._lock = threading.RLock()
        self._counters = ConnectionCounters()
        self._subscriptions: Dict[str, Tuple[int, MessageHandler]] = {}
        self._connected = False          # CONNACK received and not yet lost
        self._live = False               # connected and the disk buffer flushed: publish directly
        self._closed = False
        self.fatal: Optional[str] = None
        self._on_fatal = on_fatal
        self._on_connection_change = on_connection_change
        self._on_live = on_live          # sending is enabled (after each connect): retained state is re-sent
        self._flush_wanted = threading.Event()
        self._live_event = threading.Event()
        self._last_failure = ""
        c = params.client
        self._buffer: Optional[DiskBuffer] = None
        if c.buffer_enabled:
            self._buffer = DiskBuffer(os.path.join(resolve_path(c.buffer_directory), c.id), c.buffer_size,
                                      max_age=c.buffer_max_age)
        self.mqtt5 = mqtt5
        self.tos = 0
        self.so_priority: Optional[int] = None
        if mqtt5:   # MQTT 5: user properties, message expiry, shared subscriptions
            self._client = _PahoClient(CallbackAPIVersion.VERSION2, client_id=c.id, protocol=paho.MQTTv5)
        else:       # mqtt_client's protocol
            self._client = _PahoClient(CallbackAPIVersion.VERSION2, client_id=c.id, clean_session=c.clean_session,
                                       protocol=paho.MQTTv311)
        self._client.max_inflight_messages_set(c.max_inflight)
        self._client.reconnect_delay_set(RECONNECT_MIN_DELAY, RECONNECT_MAX_DELAY)
        if params.broker.user:
            self._client.username_pw_set(params.broker.user, params.broker.password or None)
        if c.last_will_topic:
            self._client.will_set(c.last_will_topic, c.last_will_message, c.last_will_qos, c.last_will_retained)
        if params.broker.tls_enabled:
            self._client.tls_set_context(self._tls_context())
        self._client.on_connect = self._on_connect
        self._client.on_disconnect = self._on_disconnect
        self._client.on_message = self._on_message
        self._client.on_connect_fail = self._on_connect_fail
        self._flusher = threading.Thread(target=self._flush_loop, name="micros_rt mqtt buffer", daemon=True)

    # ------------------------------------------------------------------ set-up

    def _tls_context(self) -> ssl.SSLContext:
        b, c = self.params.broker, self.params.client
        ca = resolve_path(b.tls_ca_certificate)
        try:
            ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=ca)
        except (OSError, ssl.SSLError) as exc:
            raise MqttConfigError(f"cannot load the CA certificate {ca!r} (broker/tls/ca_certificate): "
                                  f"{getattr(exc, 'strerror', None) or exc}") from exc
        if c.tls_certificate:
            cert, key = resolve_path(c.tls_certificate), resolve_path(c.tls_key)
            try:
                ctx.load_cert_chain(cert, key, password=c.tls_password or None)
            except (OSError, ssl.SSLError) as exc:
                raise MqttConfigError(f"cannot load the client certificate {cert!r} with key {key!r} "
                                      f"(client/tls/certificate, client/tls/key, client/tls/password): "
                                      f"{getattr(exc, 'strerror', None) or exc}") from exc
        return ctx

    def start(self) -> None:
        """Connect in the background (retried until :meth:`close`)."""
        as_client = f" as '{self.params.client.id}'" if self.params.client.id else ""
        _log.info("Connecting to broker at '%s'%s ...", self.uri, as_client)
        keepalive = max(1, int(round(self.params.client.keep_alive_interval)))
        if self.mqtt5:
            self._client.connect_async(self.params.broker.host, self.params.broker.port, keepalive=keepalive,
                                       clean_start=self.params.client.clean_session)
        else:
            self._client.connect_async(self.params.broker.host, self.params.broker.port, keepalive=keepalive)
        self._client.loop_start()
        self._flusher.start()

    def close(self) -> None:
        """Disconnect cleanly (no last will) and stop the network thread; harmless twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._live = False
        self._flush_wanted.set()
        try:
            self._client.disconnect()
        finally:
            self._client.loop_stop()
        self._flusher.join(timeout=2.0)

    def __enter__(self) -> "MqttConnection":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ state

    def wait_connected(self, timeout: float) -> bool:
        """Wait (bounded) until connected with the disk buffer flushed; True when so."""
        return self._live_event.wait(timeout)

    @property
    def is_connected(self) -> bool:
        """True between the broker's CONNACK and the loss of the connection."""
        return self._connected

    @property
    def is_live(self) -> bool:
        """True while messages go straight to the broker (connected, the disk buffer flushed)."""
        return self._live

    @property
    def can_send(self) -> bool:
        """True when :meth:`publish` would send or keep a message now (live, or a disk buffer)."""
        return self._live or (self._buffer is not None and not self._closed)

    def counters(self) -> ConnectionCounters:
        """A copy of the counters."""
        with self._lock:
            return dataclasses.replace(self._counters)

    # ------------------------------------------------------------------ subscribe / publish

    def subscribe(self, topic: str, qos: int, handler: MessageHandler) -> None:
        """Deliver messages of ``topic`` to ``handler``; restored after every reconnect."""
        with self._lock:
            self._subscriptions[topic] = (qos, handler)
            connected = self._connected
        if connected:
            self._client.subscribe(topic, qos)

    def unsubscribe(self, topic: str) -> None:
        """Stop delivering ``topic`` (and restoring it after reconnects)."""
        with self._lock:
            known = self._subscriptions.pop(topic, None) is not None
            connected = self._connected
        if known and connected:
            self._client.unsubscribe(topic)

    def publish(self, topic: str, payload: bytes, *, qos: int = 0, retain: bool = False,
                properties: Optional[Properties] = None) -> bool:
        """Send (or buffer on disk while disconnected); False when the message was dropped (counted)."""
        limit = self.params.client.max_packet_size
        if limit and len(payload) + len(topic.encode("utf-8")) + PUBLISH_OVERHEAD > limit:
            with self._lock:
                self._counters.dropped_too_large += 1
            _too_large.warning(topic, f"a {len(payload)}-byte message on MQTT topic '{topic}' is over "
                                      f"client/max_packet_size ({limit} bytes): dropped (further ones are counted)")
            return False
        with self._lock:
            if self._closed:
                return False
            if self._live:
                info = self._client.publish(topic, payload, qos, retain, properties)
                if info.rc == MQTTErrorCode.MQTT_ERR_SUCCESS or (info.rc == MQTTErrorCode.MQTT_ERR_NO_CONN
                                                                  and qos > 0):
                    # NO_CONN with QoS > 0: paho keeps the message and sends it after reconnecting
                    self._counters.published += 1
                    return True
                if info.rc != MQTTErrorCode.MQTT_ERR_NO_CONN:
                    self._counters.dropped_too_large += 1
                    _log.warning("micros_rt mqtt: cannot publish on '%s' (%d bytes): %s", topic, len(payload),
                                 paho.error_string(info.rc))
                    return False
            if self._buffer is None:
                self._counters.dropped_disconnected += 1
                if self._counters.dropped_disconnected == 1:
                    _log.warning("micros_rt mqtt: not connected to %s: dropping messages until the connection is "
                                 "back (set client/id and client/buffer/size to buffer them on disk)", self.uri)
                return False
            if not self._buffer.put(topic, payload, qos, retain, properties_to_dict(properties)):
                self._counters.dropped_buffer_full += 1
                if self._counters.dropped_buffer_full == 1:
                    _log.warning("micros_rt mqtt: disk buffer full (client/buffer/size = %d): dropping newer "
                                 "messages until the broker %s is back", self._buffer.size, self.uri)
                return False
            self._counters.buffered += 1
            return True

    # ------------------------------------------------------------------ paho callbacks (network thread)

    def _on_connect(self, client: paho.Client, userdata: Any, flags: Any, rc: ReasonCode, props: Any) -> None:
        if rc.is_failure:
            self._connect_refused(rc)
            return
        as_client = f" as '{self.params.client.id}'" if self.params.client.id else ""
        _log.info("Connected to broker at '%s'%s", self.uri, as_client)
        with self._lock:
            self._connected = True
            self._counters.connects += 1
            self._last_failure = ""
            subscriptions = [(t, q) for t, (q, _) in self._subscriptions.items()]
        if subscriptions:
            client.subscribe(subscriptions)
        if self.tos:
            self._mark_socket()
        self._flush_wanted.set()
        if self._on_connection_change is not None:
            self._on_connection_change(True)

    def set_tos(self, tos: int, so_priority: Optional[int] = None) -> None:
        """IP TOS (DSCP) and socket priority of the connection's socket (IPv4 or IPv6), now and after every
        reconnect."""
        self.tos = tos
        self.so_priority = so_priority
        if self._connected:
            self._mark_socket()

    def _mark_socket(self) -> None:
        sock = self._client.socket()
        try:
            if isinstance(sock, socket.socket):
                mark_socket_tos(sock, self.tos, self.so_priority)
        except OSError as exc:
            _log.warning("micros_rt mqtt: cannot set IP TOS 0x%02x on the connection to %s: %s", self.tos, self.uri,
                         exc)

    def _connect_refused(self, rc: ReasonCode) -> None:
        name = _reason_text(rc)
        if rc.value in (0x86, 0x87, 4, 5):   # bad user name or password / not authorised
            self._fail(f"the broker {self.uri} refused the connection: {name} (check broker/user and broker/pass)")
        else:
            self._log_failure(f"the broker {self.uri} refused the connection: {name}")

    def _on_disconnect(self, client: paho.Client, userdata: Any, flags: Any, rc: ReasonCode, props: Any) -> None:
        with self._lock:
            was = self._connected
            self._connected = False
            self._live = False
            self._live_event.clear()
            if was and not self._closed:
                self._counters.disconnects += 1
        if was and not self._closed:
            _log.error("Connection to broker %s lost (%s), will try to reconnect...", self.uri, _reason_text(rc))
            if self._on_connection_change is not None:
                self._on_connection_change(False)

    def _on_connect_fail(self, client: paho.Client, userdata: Any) -> None:
        exc = self._client.last_error
        if isinstance(exc, ssl.SSLCertVerificationError):
            ca = resolve_path(self.params.broker.tls_ca_certificate)
            self._fail(f"TLS handshake with {self.uri} failed: {exc.verify_message or exc}: the broker's "
                       f"certificate is not signed by the CA in {ca!r} (broker/tls/ca_certificate), or does not "
                       f"name the host '{self.params.broker.host}'")
            return
        why = f": {exc.strerror or exc}" if isinstance(exc, OSError) else ""
        self._log_failure(f"cannot reach the broker at {self.uri}{why}; retrying every {RECONNECT_MIN_DELAY} to "
                          f"{RECONNECT_MAX_DELAY} s")

    def _log_failure(self, text: str) -> None:
        with self._lock:
            repeated = text == self._last_failure
            self._last_failure = text
        if not repeated:
            _log.warning("micros_rt mqtt: %s", text)

    def _fail(self, text: str) -> None:
        if self.fatal is not None:
            return
        self.fatal = text
        _log.error("micros_rt mqtt: %s", text)
        if self._on_fatal is not None:
            self._on_fatal(text)

    def _on_message(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        with self._lock:
            self._counters.received += 1
            entry = self._subscriptions.get(message.topic)
        if entry is None:
            for pattern, candidate in list(self._subscriptions.items()):
                if pattern.startswith("$share/"):      # MQTT 5 shared subscription: $share/<group>/<filter>
                    pattern = pattern.split("/", 2)[2] if pattern.count("/") >= 2 else pattern
                if paho.topic_matches_sub(pattern, message.topic):
                    entry = candidate
                    break
        if entry is not None:
            entry[1](message.topic, bytes(message.payload), getattr(message, "properties", None))

    # ------------------------------------------------------------------ disk buffer flush

    def _flush_loop(self) -> None:
        while not self._closed:
            self._flush_wanted.wait(timeout=1.0)
            self._flush_wanted.clear()
            if self._closed or not self._connected or self._live:
                continue
            # let paho re-send its unacknowledged messages first (see the module docstring)
            time.sleep(0.1)
            self._flush()

    def _flush(self) -> None:
        while True:
            with self._lock:
                if not self._connected or self._closed:
                    return
                item = self._buffer.pop() if self._buffer is not None else None
                if item is None:
                    self._live = True
                    self._live_event.set()
                    break
                topic, payload, qos, retain, age, props = item
                assert self._buffer is not None
                if self._buffer.max_age > 0 and age > self._buffer.max_age:
                    self._counters.dropped_expired += 1
                    if self._counters.dropped_expired == 1:
                        _log.warning("micros_rt mqtt: dropping buffered messages older than %.1f s "
                                     "(client/buffer/max_age)", self._buffer.max_age)
                    continue
                try:
                    self._client.publish(topic, payload, qos, retain, properties_from_dict(props, age=age))
                except ValueError as exc:       # paho: above MQTT's 256 MB limit
                    self._counters.dropped_too_large += 1
                    _log.warning("micros_rt mqtt: dropping a buffered message on '%s': %s", topic, exc)
                    continue
                self._counters.flushed += 1
        if self._on_live is not None:
            try:
                self._on_live()
            except Exception:   # a bug in the callback must not stop the flush thread
                _log.exception("micros_rt mqtt: re-sending after connecting to %s failed", self.uri)
