"""The microcontroller link itself: one UDP socket for topics, TCP for service calls, wire counters.

* :class:`McuLink` owns the UDP socket (bound to ``bind``), its receive thread and the bridge's service
  server (calls *from* the board), and makes service calls *to* the board (one TCP connection each).
* :class:`UdpWriter` (a :class:`~micros_rt.transports.base.TransportWriter`) sends one stream to the board:
  ``prepare`` encodes and refuses what does not fit the mtu, ``send`` sends one datagram with the
  stream's IP TOS.
* :class:`UdpReader` (a :class:`~micros_rt.transports.base.PushReader`) decodes one stream's datagrams on
  the receive thread and queues the messages for the subscription that takes them.

The link applies no QoS (time filter, lifespan, deadline): micros_rt's core does, in the subscriptions the
bridge makes (:mod:`micros_rt.bridges.mcu`). It counts what only it can see (:class:`LinkStats`): datagrams
sent, oversized or refused by the kernel, service calls, and bad input, which never stops anything: each
problem is counted (section ``bad_input``) and reported in words once per peer and kind (then counted; a
summary line at most every 30 s).
"""

from __future__ import annotations

import errno
import json
import select
import socket
import struct
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import genpy

from micros_rt.log import nonblocking_logger
from micros_rt.exceptions import TransportError
from micros_rt.ratelimit import RateLimitedLog
from micros_rt.transports.base import PushReader
from micros_rt.transports.marking import mark_socket
from micros_rt.qos.options import TransportPriority, priority_tos

from . import wire
from .spec import McuConfig, ServiceEntry, TopicEntry
from .errors import DatagramTooLargeError, McuServiceError, WireError

__all__ = ["LinkStats", "McuLink", "UdpWriter", "UdpReader", "ServiceHandler", "PROTOCOL"]

PROTOCOL = "MCU-UDP"
_log = nonblocking_logger("rosout.micros_rt.mcu")

#: Largest service frame accepted from the board (bytes before END).
MAX_FRAME = 65536
#: A board's service call must arrive complete (up to END) within this many seconds.
FRAME_TIMEOUT = 5.0
#: Calls from the board handled at once; more connections are closed at once and counted ``busy``.
MAX_CONCURRENT_CALLS = 4
#: Messages a reader holds by default between the receive thread and its taker (the oldest is dropped first).
READER_QUEUE = 1000

#: (name of the service entry, its params) -> the response's fields, or raise McuServiceError/WireError.
ServiceHandler = Callable[[ServiceEntry, List[Any]], Dict[str, Any]]  # (entry, what follows the name)


class LinkStats:
    """The link's wire counters (thread-safe), by section and entry: datagrams, bad input, service calls.

    >>> s = LinkStats(); s.add("bad_input", "not_msgpack"); s.snapshot()["bad_input"]
    {'not_msgpack': 1}
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: Dict[str, Dict[str, Any]] = {}

    def declare(self, section: str, entry: str, keys: Sequence[str]) -> None:
        """Show ``keys`` of ``entry`` as zeros until they count something."""
        with self._lock:
            self._counts.setdefault(section, {}).setdefault(entry, {k: 0 for k in keys})

    def add(self, section: str, key: str, n: int = 1, *, entry: Optional[str] = None) -> None:
        with self._lock:
            counts = self._counts.setdefault(section, {})
            if entry is not None:
                counts = counts.setdefault(entry, {})
            counts[key] = counts.get(key, 0) + n

    def set(self, section: str, key: str, value: Any) -> None:
        """A value that is not a count (e.g. ``link.wire_form``, the form written to the board)."""
        with self._lock:
            self._counts.setdefault(section, {})[key] = value

    def get(self, section: str, key: str, *, entry: Optional[str] = None) -> int:
        with self._lock:
            counts = self._counts.get(section, {})
            if entry is not None:
                counts = counts.get(entry, {})
            return int(counts.get(key, 0))

    def snapshot(self) -> Dict[str, Any]:
        """A deep copy of every counter."""
        with self._lock:
            return json.loads(json.dumps(self._counts))  # type: ignore[no-any-return]


def _tos_cmsg(tos: int, v6: bool) -> List[Tuple[int, int, bytes]]:
    if tos == 0:
        return []
    if v6:
        return [(socket.IPPROTO_IPV6, socket.IPV6_TCLASS, struct.pack("i", tos))]
    return [(socket.IPPROTO_IP, socket.IP_TOS, struct.pack("i", tos))]


class UdpWriter:
    """One stream to the board, a :class:`~micros_rt.transports.base.TransportWriter`: ``prepare`` encodes and
    refuses what does not fit the mtu, ``send`` sends one datagram with the stream's IP TOS. QoS (time filter,
    lifespan) is the core's: the bridge's subscription applies it before its callback sends. Counts its wire
    outcomes (``sent``, ``oversized``, ``send_failed``) in the link's counters.

    >>> writer.prepare(big_message)                       # doctest: +SKIP
    DatagramTooLargeError: /cmd: the message encodes to 2,013 bytes, more than ... mtu of 1,472 ...
    """

    protocol = PROTOCOL

    def __init__(self, link: "McuLink", entry: TopicEntry) -> None:
        self._link = link
        self.entry = entry
        self.codec = wire.codec_for(entry.data_class)
        board = link.config.microcontroller
        self.guid = f"udp://{board.address}:{board.topic_port}/{entry.name}"
        self.tos = priority_tos(entry.advertise.transport_priority)
        self._cmsg = _tos_cmsg(self.tos, board.family_v6)
        self.closed = False
        link.stats.declare("to_microcontroller", entry.name, ("sent", "oversized", "send_failed"))

    def prepare(self, msg: Any) -> bytes:
        """The datagram for ``msg``; :class:`DatagramTooLargeError` when it exceeds the mtu (counted
        ``oversized``), ``genpy.SerializationError`` on a bad field value (counted ``send_failed``)."""
        try:
            data = wire.encode_datagram(self.entry.name, self.codec.to_wire(msg), form=self._link.wire_form)
        except genpy.SerializationError:
            self._link.stats.add("to_microcontroller", "send_failed", entry=self.entry.name)
            raise
        if len(data) > self._link.config.mtu:
            self._link.stats.add("to_microcontroller", "oversized", entry=self.entry.name)
            raise DatagramTooLargeError(self.entry.topic, len(data), self._link.config.mtu)
        return data

    def send(self, prepared: bytes) -> None:
        """Send one datagram to the board without blocking (counted ``sent``); :class:`TransportError`
        (counted ``send_failed``) when the kernel refuses or the writer or link is closed."""
        if self.closed:
            raise TransportError(f"microcontroller link: the writer of {self.entry.topic} is closed; "
                                 f"open another with McuLink.open_writer")
        try:
            self._link.send_datagram(prepared, self._cmsg)
        except TransportError:
            self._link.stats.add("to_microcontroller", "send_failed", entry=self.entry.name)
            raise
        self._link.stats.add("to_microcontroller", "sent", entry=self.entry.name)

    def close(self) -> None:
        """Refuse further sends (the socket is the link's); harmless twice."""
        self.closed = True


class UdpReader(PushReader):
    """One stream from the board, a pushed :class:`~micros_rt.transports.base.TransportReader`: the receive
    thread decodes each datagram (a malformed one is counted in ``bad_input`` and dropped) and queues the
    message; ``take`` hands them over oldest first. Enforces no QoS itself (the subscription does)."""

    def __init__(self, link: "McuLink", entry: TopicEntry, depth: Optional[int], wake: Callable[[], None]) -> None:
        board = link.config.microcontroller
        self.guid = f"udp://{board.address}:{board.topic_port}/{entry.name}"
        super().__init__(PROTOCOL, depth, wake, blocking=False, links=self._heard)
        self.entry = entry
        self.codec = wire.codec_for(entry.data_class)
        self._link = link
        self._last_source: Optional[str] = None

    def _heard(self) -> Dict[str, str]:
        return {self.guid: PROTOCOL} if self._last_source is not None else {}

    def decode_datagram(self, payload: bytes) -> Any:
        """The ROS message of one datagram; :class:`WireError` (a ``ValueError``) when malformed."""
        return self._decode(wire.split_payload(payload))

    def _decode(self, payload: wire.Payload) -> Any:
        try:
            return self.codec.from_args(payload.rest)
        except WireError as exc:
            raise WireError(exc.kind, f"stream {payload.name!r} ({self.entry.type}): {exc}") from exc

    def put_datagram(self, datagram: bytes, source: str) -> None:
        """From the receive thread: decode one datagram and queue its message (never waits: the oldest is
        dropped when the queue is full, counted in :attr:`dropped`)."""
        try:
            payload = wire.split_payload(datagram)
        except WireError as exc:
            self._link.bad_input(source, exc, "a datagram")
            return
        self.put_payload(payload, source)

    def put_payload(self, payload: wire.Payload, source: str) -> None:
        """:meth:`put_datagram` of a datagram already split; a well-formed one also tells the link the
        board's era (:meth:`McuLink.heard_form`)."""
        try:
            msg = self._decode(payload)
        except WireError as exc:
            self._link.bad_input(source, exc, "a datagram")
            return
        self._last_source = source
        self._link.heard_form(payload.form(self.codec.field_count), f"a datagram of {payload.name!r}")
        self.put(msg, 0, source)


class McuLink:
    """The sockets of one bridge: UDP for topics, TCP for services. Use as a context manager.

    ``open_writer``/``open_reader`` give the per-stream ends; ``serve_calls(handler)`` answers the board's
    service calls; ``call(entry, params)`` calls a service the board serves.
    """

    def __init__(self, config: McuConfig, *, stats: Optional[LinkStats] = None) -> None:
        self.config = config
        self.stats = stats or LinkStats()
        self._board_ip = config.microcontroller.address
        self._family = socket.AF_INET6 if config.microcontroller.family_v6 else socket.AF_INET
        self._readers: Dict[str, UdpReader] = {}
        self._closed = threading.Event()
        self._threads: List[threading.Thread] = []
        self._ratelimit = RateLimitedLog(_log, interval=30.0)
        self._handler: Optional[ServiceHandler] = None
        self._services: Dict[str, ServiceEntry] = {e.name: e for e in config.services_for_microcontroller}
        self._slots = threading.Semaphore(MAX_CONCURRENT_CALLS)
        self._tcp: Optional[socket.socket] = None
        self._form_lock = threading.Lock()
        self._learned: Optional[wire.WireForm] = None   # the era the board's own bytes showed (wire_form unset)
        self.stats.set("link", "wire_form", self.wire_form.value)
        self._udp = self._bind(socket.SOCK_DGRAM, config.bind.topic_port, "topic")
        self._udp.settimeout(0.2)
        self._start(self._receive_loop, "mcu-link udp")

    # -- life cycle
    def _bind(self, kind: int, port: int, what: str) -> socket.socket:
        sock = socket.socket(self._family, kind)
        try:
            if kind == socket.SOCK_STREAM:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.config.bind.address, port))
        except OSError as exc:
            sock.close()
            kind_name = "UDP" if kind == socket.SOCK_DGRAM else "TCP"
            hint = " (is another mcu-bridge running? change bind.{}_port)".format(what) \
                if exc.errno == errno.EADDRINUSE else ""
            raise TransportError(f"microcontroller link: cannot bind {kind_name} "
                                 f"{self.config.bind.address}:{port} for {what}s: {exc.strerror}{hint}") from exc
        return sock

    def _start(self, target: Callable[[], None], name: str) -> None:
        t = threading.Thread(target=target, name=name, daemon=True)
        t.start()
        self._threads.append(t)

    def close(self) -> None:
        """Stop the threads and close the sockets; harmless twice."""
        if self._closed.is_set():
            return
        self._closed.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._udp.close()
        if self._tcp is not None:
            self._tcp.close()
        for reader in self._readers.values():
            reader.close()

    def __enter__(self) -> "McuLink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the board's era
    @property
    def wire_form(self) -> wire.WireForm:
        """The form written to the board now: ``wire_form`` when the configuration sets it, else the era the
        board's own datagrams and requests showed last (:meth:`heard_form`), else
        :data:`~micros_rt.transports.mcu.wire.DEFAULT_WIRE_FORM` (CVRA's final form) until it has sent any."""
        return self.config.wire_form or self._learned or wire.DEFAULT_WIRE_FORM

    def heard_form(self, form: Optional[wire.WireForm], what: str) -> None:
        """The board sent ``what`` laid out in ``form`` (None: a layout several eras share, which tells
        nothing): from now on the link writes that form, unless the configuration sets ``wire_form``.
        Each change is one log line and counted (``link.wire_form_changes``); ``link.wire_form`` names the
        form in use."""
        if form is None or form is self._learned:
            return
        with self._form_lock:
            before, self._learned = self._learned, form
        if before is form:
            return
        self.stats.add("link", "wire_form_changes")
        self.stats.set("link", "wire_form", self.wire_form.value)
        if self.config.wire_form is not None:
            if before is None and form is not self.config.wire_form:
                _log.warning("microcontroller link: the board at %s sends CVRA's %s form (%s) but wire_form is "
                             "%s: the bridge writes %s as configured (remove wire_form to follow the board)",
                             self._board_ip, form.value, what, self.config.wire_form.value,
                             self.config.wire_form.value)
            return
        _log.info("microcontroller link: the board at %s speaks CVRA's %s form (%s)%s; the bridge now writes that "
                  "form to it (wire_form in the configuration would fix one)", self._board_ip, form.value, what,
                  "" if before is None else f", no longer {before.value}")

    # -- logging
    def warn(self, key: Any, message: str, *, group: Any = None) -> None:
        """A warning once per ``key``, then counted (see :class:`RateLimitedLog`)."""
        self._ratelimit.warning(key, message, group=group)

    def bad_input(self, peer: str, err: WireError, what: str) -> None:
        """Count one bad datagram/frame and say so, once per peer and kind."""
        self.stats.add("bad_input", err.kind)
        self.warn((peer.rsplit(":", 1)[0], err.kind),
                  f"microcontroller link: {what} from {peer} dropped ({err.kind}): {err}. The bridge goes on; "
                  f"further ones from this peer are counted in ~stats bad_input.{err.kind}", group=err.kind)

    def internal_error(self, exc: BaseException, what: str) -> None:
        """An unexpected exception on one of the link's threads: counted (``link.internal_errors``), logged."""
        self.stats.add("link", "internal_errors")
        self.warn(("internal", type(exc).__name__), f"microcontroller link: internal error {what}: "
                  f"{type(exc).__name__}: {exc} (please report it; the link goes on)", group="internal")

    # -- topics
    def open_writer(self, entry: TopicEntry) -> UdpWriter:
        return UdpWriter(self, entry)

    def open_reader(self, entry: TopicEntry, depth: Optional[int] = READER_QUEUE,
                    wake: Callable[[], None] = lambda: None) -> UdpReader:
        """The reader of ``entry``'s datagrams: its queue keeps the newest ``depth`` messages (None:
        unbounded); ``wake`` is called after each (the subscription's delivery thread waits on it)."""
        reader = UdpReader(self, entry, depth, wake)
        self._readers[entry.name] = reader
        return reader

    def send_datagram(self, data: bytes, cmsg: List[Tuple[int, int, bytes]]) -> None:
        if self._closed.is_set():
            raise TransportError("microcontroller link: closed")
        board = self.config.microcontroller
        try:
            self._udp.sendmsg([data], cmsg, socket.MSG_DONTWAIT, board.topic())
        except BlockingIOError as exc:
            raise TransportError(f"the socket's send buffer is full; datagram to {board.address}:"
                                 f"{board.topic_port} dropped") from exc
        except OSError as exc:
            raise TransportError(f"cannot send to {board.address}:{board.topic_port}: {exc.strerror}") from exc

    def _socket_loop(self, receive: Callable[[], Tuple[Any, Any]], handle: Callable[[Any, Any], None]) -> None:
        """Until closed: ``handle(*receive())``; the socket's 0.2 s timeout lets it notice ``close()``."""
        while not self._closed.is_set():
            try:
                item, addr = receive()
            except socket.timeout:
                continue
            except OSError:
                if self._closed.is_set():
                    return
                time.sleep(0.05)
                continue
            try:
                handle(item, addr)
            except Exception as exc:  # a bug must not end the loop: say it (once a kind), count it, go on
                self.internal_error(exc, f"handling input from {addr}")

    def _receive_loop(self) -> None:
        self._socket_loop(lambda: self._udp.recvfrom(65536),
                          lambda data, addr: self._datagram(data, f"{addr[0]}:{addr[1]}", addr[0]))

    def _datagram(self, data: bytes, peer: str, ip: str) -> None:
        if ip != self._board_ip:
            self.bad_input(peer, WireError("foreign_sender", f"only {self._board_ip} (microcontroller.address) "
                                                             f"may send datagrams to the bridge"), "a datagram")
            return
        try:
            payload = wire.split_payload(data)
        except WireError as exc:
            self.bad_input(peer, exc, "a datagram")
            return
        reader = self._readers.get(payload.name)
        if reader is None:
            self.bad_input(peer, _unknown("unknown_stream", "from_microcontroller", payload.name, self._readers),
                           "a datagram")
            return
        reader.put_payload(payload, peer)

    # -- services: calls from the board
    def serve_calls(self, handler: ServiceHandler) -> None:
        """Listen on ``bind.service_port`` for the board's calls and answer them with ``handler``."""
        self._handler = handler
        self._tcp = self._bind(socket.SOCK_STREAM, self.config.bind.service_port, "service")
        self._tcp.listen(16)
        self._tcp.settimeout(0.2)
        self._start(self._accept_loop, "mcu-link tcp")

    def _accept_loop(self) -> None:
        assert self._tcp is not None
        self._socket_loop(self._tcp.accept, self._accepted)

    def _accepted(self, conn: socket.socket, addr: Any) -> None:
        peer = f"{addr[0]}:{addr[1]}"
        if addr[0] != self._board_ip:
            conn.close()
            self.bad_input(peer, WireError("foreign_sender", f"only {self._board_ip} (microcontroller.address) "
                                                             f"may call services through the bridge"),
                           "a service call")
            return
        if not self._slots.acquire(blocking=False):
            conn.close()
            self.stats.add("bad_input", "busy")
            self.warn((addr[0], "busy"), f"microcontroller link: a service call from {peer} was refused: "
                      f"{MAX_CONCURRENT_CALLS} calls are already in progress", group="busy")
            return
        threading.Thread(target=self._serve_one, args=(conn, peer), name="mcu-link call", daemon=True).start()

    def _serve_one(self, conn: socket.socket, peer: str) -> None:
        try:
            with conn:
                try:
                    body = _read_frame(conn, time.monotonic() + FRAME_TIMEOUT)
                    request = wire.decode_request_payload(body)
                except WireError as exc:
                    self.bad_input(peer, exc, "a service frame")
                    return
                entry = self._services.get(request.name)
                if entry is None:
                    self.bad_input(peer, _unknown("unknown_service", "services_for_microcontroller", request.name,
                                                  self._services), "a service call")
                    return
                assert self._handler is not None
                self.stats.add("services_for_microcontroller", "calls", entry=entry.name)
                fields = wire.codec_for(entry.service_class._request_class).field_count
                self.heard_form(request.form(fields), f"a call of {entry.name!r}")
                try:
                    answer = self._handler(entry, request.rest)
                except WireError as exc:
                    self.stats.add("services_for_microcontroller", "failed", entry=entry.name)
                    self.bad_input(peer, exc, f"a call of {entry.name!r}")
                    return
                except McuServiceError as exc:
                    self.stats.add("services_for_microcontroller", "failed", entry=entry.name)
                    self.warn((peer.rsplit(":", 1)[0], "call_failed", entry.name),
                              f"microcontroller link: the board's call of {entry.service} failed: {exc}; it gets "
                              f"no answer (the connection is closed)", group="call_failed")
                    return
                _set_tos(conn, entry.advertise.transport_priority, self._family)
                conn.sendall(wire.encode_response(answer, form=self.wire_form))
                self.stats.add("services_for_microcontroller", "ok", entry=entry.name)
        except OSError as exc:
            self.warn((peer.rsplit(":", 1)[0], "socket"), f"microcontroller link: service connection from {peer}: "
                      f"{exc}", group="socket")
        except Exception as exc:  # e.g. a ROS service answering a value its own type cannot carry
            self.internal_error(exc, f"serving a call from {peer}")
        finally:
            self._slots.release()

    # -- services: calls to the board
    def call(self, entry: ServiceEntry, params: Dict[str, Any]) -> Any:
        """Call the board's service ``entry`` with the request's fields ``params`` (written in the link's
        ``wire_form``); the undecoded answer (one MessagePack object: a map, an array, a bare value or nil).

        Raises :class:`McuServiceError` naming the board and the service when it cannot connect, does not
        answer within ``entry.timeout``, closes the connection without answering (whatever the response
        type: an empty response is answered with nil) or answers something that is not MessagePack.
        """
        board = self.config.microcontroller
        where = f"the microcontroller at {board.address}:{board.service_port}"
        deadline = time.monotonic() + entry.timeout
        self.stats.add("services_on_microcontroller", "calls", entry=entry.name)
        try:
            with socket.socket(self._family, socket.SOCK_STREAM) as sock:
                if self.config.bind.address not in ("0.0.0.0", "::"):
                    sock.bind((self.config.bind.address, 0))
                _set_tos(sock, entry.advertise.transport_priority, self._family)
                sock.settimeout(max(deadline - time.monotonic(), 0.001))
                sock.connect(board.service())
                sock.sendall(wire.encode_request(entry.name, params, form=self.wire_form))
                chunks: List[bytes] = []
                size = 0
                while True:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise socket.timeout()
                    sock.settimeout(left)
                    chunk = sock.recv(65536)
                    if not chunk:
                        break
                    chunks.append(chunk)
                    size += len(chunk)
                    if size > MAX_FRAME:
                        raise McuServiceError(f"{where} answered {entry.service} with more than {MAX_FRAME:,} bytes")
            if not chunks:
                self.stats.add("services_on_microcontroller", "failed", entry=entry.name)
                raise McuServiceError(
                    f"{where} closed the connection without answering {entry.service} ({entry.name!r}): the call "
                    f"failed or the board has no service named {entry.name!r}. A board answers even an empty "
                    f"response (with nil); CVRA's C firmware closes without answering when a handler fails, and "
                    f"CVRA's Python server when its handler returns None")
            answer = wire.decode_response(b"".join(chunks))
        except socket.timeout:
            self.stats.add("services_on_microcontroller", "timeout", entry=entry.name)
            raise McuServiceError(f"{where} did not answer {entry.service} ({entry.name!r}) within "
                                  f"{entry.timeout:g} s (timeout: in the bridge configuration)") from None
        except WireError as exc:
            self.stats.add("services_on_microcontroller", "failed", entry=entry.name)
            raise McuServiceError(f"{where} answered {entry.service} with something that is not one MessagePack "
                                  f"object: {exc}") from exc
        except OSError as exc:
            self.stats.add("services_on_microcontroller", "failed", entry=entry.name)
            raise McuServiceError(f"cannot call {entry.service} ({entry.name!r}) on {where}: "
                                  f"{exc.strerror or exc}") from exc
        return answer


def _unknown(kind: str, section: str, name: str, known: Dict[str, Any]) -> WireError:
    configured = ", ".join(repr(n) for n in known) or "none"
    return WireError(kind, f"no {section} entry is named {name[:60]!r} (configured: {configured})")


def _set_tos(sock: socket.socket, priority: TransportPriority, family: int) -> None:
    mark_socket(sock, priority, family=family)  # DSCP and SO_PRIORITY, IPv4 or IPv6: the one helper


def _read_frame(conn: socket.socket, deadline: float) -> bytes:
    """One serial datagram's body (up to END) from ``conn``; WireError ``no_end`` on EOF or timeout first."""
    reader = wire.FrameReader(MAX_FRAME)
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise WireError("no_end", f"no SLIP END (0xC0) within {FRAME_TIMEOUT:g} s "
                                      f"({reader.pending} bytes received)")
        ready, _, _ = select.select([conn], [], [], left)
        if not ready:
            continue
        chunk = conn.recv(65536)
        if not chunk:
            raise WireError("no_end", f"the connection was closed before a SLIP END (0xC0) "
                                      f"({reader.pending} bytes received)")
        body = reader.feed(chunk)
        if body is not None:
            return body
