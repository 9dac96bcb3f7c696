"""Shared-memory channels (iceoryx2): one per publisher and subscriber that negotiated SHM.

A channel is an iceoryx2 publish-subscribe service with one publisher port and one subscriber port, and an
event service beside it that wakes the subscriber. One channel per pair, not one service per topic:

- nothing arrives twice: a subscriber reads only the publishers that chose SHM for it (over a topic-wide
  service it would also read those that serve it over DDS or TCPROS);
- back-pressure is per subscriber: iceoryx2's blocking send holds Python's GIL (measured: a sender blocked
  on a full subscriber stopped the whole process, the subscriber's own thread included), so a lossless
  channel refuses when full (``DiscardData``) and :class:`ShmWriter` retries with
  :func:`~micros_rt.transports.base.send_with_backoff`, which sleeps without the GIL; over a topic-wide
  service a retry would send again to the subscribers that already took the sample;
- QoS is per pair: the first creator of an iceoryx2 service fixes its limits.

Each sample is ``<seq u64><source time ns u64>`` then the ROS 1 serialization of the message. The sequence
number counts per channel, so a subscriber counts what a KEEP_LAST channel overwrote (``queue_size``: the
newest are kept, as ROS does) as dropped.
"""

from __future__ import annotations

import binascii
import ctypes
import io
import itertools
import operator
import os
import struct
import threading
import time
from typing import Any, Callable, Dict, Optional, Tuple, Type

import genpy

from ...exceptions import MicrosRtError, PublishTimeoutError, TransportError
from ...log import nonblocking_logger
from ...negotiation.protocol import SHM
from ..base import send_with_backoff
from .host import (ATTACH_TIMEOUT, PeerProcess, cleanup_dead_nodes, commit_segments, iceoryx2, shm_free_bytes,
                   shm_node, warn_if_full, why_failed)

__all__ = ["MalformedFrameError", "ShmChannel", "ShmLink", "ShmWriter", "TRANSIT_DEPTH", "PUBLISH_BLOCK_TIMEOUT",
           "decode_frame"]

_log = nonblocking_logger("rosout.micros_rt.shm")

_HEAD = struct.Struct("<QQ")
#: Most samples a channel holds for its subscriber: a lossless one's (the publisher waits beyond it), and a
#: KEEP_LAST one's when the publisher's ``queue_size`` is larger. Only the slots in use take memory (iceoryx2
#: reuses the last freed slot first: 300 MB sent 1 MB at a time to a subscriber that keeps up took 1 MB of
#: /dev/shm); a subscriber that stops holds at most this many messages, as a TCP socket buffer would.
TRANSIT_DEPTH = 64
#: A lossless channel's data segment is committed up front (issue 46) and holds its 64 slots: it grows with
#: the messages up to this many bytes (64 slots of a 6 MB image would take 400 MB of /dev/shm); a message larger
#: than a slot then goes in pieces of a slot, which the subscriber puts together. Nothing is lost either way.
LOSSLESS_CHANNEL_BYTES = 32 << 20
#: The smallest slot a channel starts with.
MIN_SLOT = 1024
#: /dev/shm room a channel leaves to others when it grows.
GROW_MARGIN = 16 << 20
#: A piece of a message: its frame's sequence number has this bit, and ``<total u32><offset u32>`` follow the
#: header. Sequence numbers never reach it (2**63 messages).
PIECE = 1 << 63
_PIECE_HEAD = struct.Struct("<QQII")
#: The largest message a channel puts together from pieces.
MAX_PIECED = 1 << 30
#: How long a lossless (``queue_size=None``) publish() waits for a subscriber that does not keep up.
PUBLISH_BLOCK_TIMEOUT = 10.0
#: The link thread's wait between looks at whether its publisher is still there.
_POLL = 0.5
#: A received sample's payload length in bytes (its ``Slice[c_uint8]``): iceoryx2's own ``payload()`` builds a
#: Slice through ``typing.get_origin`` on every call: the delivery thread took 15 % more CPU per small message.
_slice_len = operator.attrgetter("__slice_len")

_ids = itertools.count(1)


class MalformedFrameError(MicrosRtError, ValueError):
    """A shared-memory sample that is not a micros_rt frame of the expected message type."""


class _Bounded(bytes):
    """A frame's message bytes that refuse a read past their end: genpy cuts a string or array that a frame's
    length fields say is longer than the frame short, silently (issue 46: a fake publisher's truncated frames
    reached the callback with the wrong data length). Measured: +0.3 us per std_msgs/String decode."""

    __slots__ = ()

    def __getitem__(self, key: Any) -> Any:
        if key.__class__ is slice and key.stop is not None and key.stop > len(self):
            raise ValueError(f"the message's length fields need {key.stop} bytes, the frame holds {len(self)}")
        return bytes.__getitem__(self, key)


#: Most messages a channel may have overwritten between two samples its subscriber takes (a KEEP_LAST channel
#: of a fast publisher and a stalled subscriber); a larger gap is not believed (issue 46: a frame numbered
#: 2**64-1 made the statistics count 1.8e19 drops).
MAX_SEQ_GAP = 1 << 32


def decode_frame(data_class: Type[genpy.Message], frame: bytes, last: int = 0) -> Tuple[int, int, Any]:
    """(sequence number, source time ns, message) of one channel sample whose predecessor was numbered
    ``last``; MalformedFrameError in words for a frame that is short, whose message does not fit it exactly,
    or whose number is not after ``last`` (within :data:`MAX_SEQ_GAP`)."""
    if len(frame) < 16:
        raise MalformedFrameError(f"a shared-memory sample of {len(frame)} bytes is shorter than micros_rt's "
                                  f"16-byte frame header")
    seq, source_ns = _HEAD.unpack_from(frame, 0)
    if not last < seq <= last + MAX_SEQ_GAP:
        raise MalformedFrameError(f"a shared-memory sample numbered {seq} follows number {last} on its channel "
                                  f"(numbers grow by 1 per message; at most {MAX_SEQ_GAP} may be overwritten)")
    msg = data_class()
    body = _Bounded(memoryview(frame)[16:])  # one copy
    try:
        msg.deserialize(body)
    except (genpy.DeserializationError, struct.error, ValueError, TypeError, UnicodeError, IndexError) as exc:
        raise MalformedFrameError(f"a shared-memory sample of {len(frame)} bytes does not decode as "
                                  f"{data_class._type} ({exc}); is the publisher's type really "
                                  f"{data_class._type}?") from exc
    return seq, source_ns, msg


def _pow2(n: int) -> int:
    """The smallest power of two >= n."""
    return 1 << max(0, n - 1).bit_length()


def _channel_name() -> str:
    return f"micros_rt/{os.getpid():08x}{next(_ids):08x}{binascii.hexlify(os.urandom(4)).decode()}"


def _services(name: str, *, create: bool, lossless: bool = False, latch: bool = False,
              depth: int = TRANSIT_DEPTH) -> Tuple[Any, Any]:
    iox2 = iceoryx2()
    node = shm_node()
    service_name = iox2.ServiceName.new(name)
    pubsub = node.service_builder(service_name).publish_subscribe(iox2.Slice[ctypes.c_uint8])
    events = node.service_builder(service_name).event()
    if not create:
        return pubsub.open(), events.open()
    pubsub = (pubsub.max_publishers(1).max_subscribers(1).max_nodes(4)
              .subscriber_max_buffer_size(depth).history_size(1 if latch else 0)
              .enable_safe_overflow(not lossless))
    return pubsub.create(), events.create()


class ShmChannel:
    """The publisher's end of one channel."""

    def __init__(self, subscriber: str, *, lossless: bool, latch: bool, initial_len: int,
                 depth: int = TRANSIT_DEPTH, peer_pid: int = 0) -> None:
        iox2 = iceoryx2()
        self.subscriber = subscriber
        self.lossless = lossless
        self._slots = depth + 4  # iceoryx2's samples: the subscriber's buffer, history and loans
        self.peer_pid = peer_pid    # the subscriber's process (0: unknown)
        self._peer = PeerProcess(peer_pid)
        # held while a port is used or deleted: iceoryx2 aborts the process on a deleted port's use
        self._lock = threading.Lock()
        self.name = _channel_name()
        self.closed = False
        self._deleted = False       # the ports were let go (by close() or by the lock's holder after it)
        self.seen = False           # the subscriber's port attached at least once
        self.created = time.monotonic()
        self._service, events = _services(self.name, create=True, lossless=lossless, latch=latch, depth=depth)
        #: the largest sample the committed data segment holds (a larger one makes iceoryx2 grow it)
        self.capacity = _pow2(max(initial_len, MIN_SLOT))
        #: the largest it may grow to (lossless: a bounded segment, larger messages go in pieces)
        self.max_slot = (max(MIN_SLOT, _pow2(LOSSLESS_CHANNEL_BYTES // self._slots + 1) // 2) if lossless
                         else 1 << 62)
        self.capacity = min(self.capacity, self.max_slot)
        self.pieced = 0  # messages sent in pieces
        self._piecing: Optional[Tuple[bytes, int, int, int]] = None  # (body, seq, source ns, next offset)
        self._publisher = (self._service.publisher_builder().initial_max_slice_len(self.capacity)
                           .allocation_strategy(iox2.AllocationStrategy.PowerOfTwo)
                           .backpressure_strategy(iox2.BackpressureStrategy.DiscardData).create())
        self._events = events
        self._notifier = events.notifier_builder().create()
        self._seq = 0
        try:
            commit_segments()  # the kernel says no now, or never (no SIGBUS at a first touch)
        except TransportError:
            self.close()
            raise

    def attached(self) -> bool:
        """The subscriber's port is there now (a SIGKILLed one only after its node was cleaned up)."""
        service = self._service
        if service is None:
            return False
        attached = bool(service.dynamic_config.number_of_subscribers > 0)
        if attached:
            self.seen = True
        return attached

    def try_send(self, body: bytes, source_ns: int = 0) -> bool:
        """Put one message into the channel, stamped now (or ``source_ns``); False when it was not taken (a
        lossless channel full, or no subscriber attached: then a latched channel keeps it as history). A
        lossless message larger than a slot goes in pieces: False then means "not all yet", and the next call
        with the same ``body`` goes on where this one stopped. Raises TransportError when the channel must grow
        and /dev/shm has no room (a KEEP_LAST channel; a lossless one goes in pieces instead)."""
        n = len(body)
        if self.closed:
            return False
        self._lock.acquire()  # held by another sender at most (close() never waits for it)
        try:
            if self.closed:
                return False
            if n + 16 > self.capacity:
                self._grow(n + 16)
            if n + 16 > self.capacity:
                return self._send_pieces(body, source_ns)
            self._piecing = None
            sample = self._publisher.loan_slice_uninit(n + 16)
            ptr = sample.payload_ptr
            seq = self._seq + 1
            ctypes.memmove(ptr, _HEAD.pack(seq, source_ns or time.time_ns()), 16)
            ctypes.memmove(ptr + 16, body, n)
            if not sample.assume_init().send():
                return False
            self._seq = seq
            self._notifier.notify()
            return True
        finally:
            self._lock.release()
            if self.closed:
                self._delete_ports()  # close() came while we held the lock (a signal handler): it is ours to do

    def _grow(self, need: int) -> None:
        """Let iceoryx2 make a larger data segment and commit it before a byte is written to it, if /dev/shm has
        the room (else the channel stays as it is: a lossless one sends pieces, a KEEP_LAST one fails)."""
        target = min(_pow2(need), self.max_slot)
        if target <= self.capacity:
            return
        free = shm_free_bytes()
        if free < self._slots * target + GROW_MARGIN:
            if self.lossless:
                return
            raise TransportError(f"/dev/shm has {free >> 20} MiB free, not enough for a channel of {self._slots} "
                                 f"messages of {need} bytes (df -h /dev/shm)")
        sample = self._publisher.loan_slice_uninit(target)  # iceoryx2 grows its segment here
        try:
            commit_segments()
        finally:
            sample.delete()
        self.capacity = target

    def _send_pieces(self, body: bytes, source_ns: int) -> bool:
        piecing = self._piecing
        if piecing is None or piecing[0] is not body:
            piecing = (body, self._seq + 1, source_ns or time.time_ns(), 0)
        _, seq, ns, offset = piecing
        total = len(body)
        step = self.capacity - _PIECE_HEAD.size
        address = ctypes.cast(ctypes.c_char_p(body), ctypes.c_void_p).value or 0
        while offset < total:
            part = min(step, total - offset)
            sample = self._publisher.loan_slice_uninit(_PIECE_HEAD.size + part)
            ptr = sample.payload_ptr
            ctypes.memmove(ptr, _PIECE_HEAD.pack(seq | PIECE, ns, total, offset), _PIECE_HEAD.size)
            ctypes.memmove(ptr + _PIECE_HEAD.size, address + offset, part)
            if not sample.assume_init().send():
                self._piecing = (body, seq, ns, offset)
                return False
            self._notifier.notify()
            offset += part
        self._piecing = None
        self._seq = seq
        self.pieced += 1
        return True

    def update_connections(self) -> None:
        """Hand a newly attached subscriber the history (a latched topic's last message)."""
        with self._lock:
            if not self.closed:
                self._publisher.update_connections()
        if self.closed:
            self._delete_ports()

    def subscriber_dead(self) -> bool:
        """The subscriber's process is gone (SIGKILLed: its port stays in the service until cleaned up)."""
        return not self._peer.alive()

    def close(self) -> None:
        """Stop the channel; never waits: a signal handler (rospy's shutdown hooks) may run it in the very thread
        that holds the lock inside :meth:`try_send`, so whoever holds the lock deletes the ports on letting go of
        it (iceoryx2 aborts the process on a deleted port's use). Harmless twice."""
        self.closed = True
        self._peer.close()
        self._delete_ports()

    def _delete_ports(self) -> None:
        if self._deleted or not self._lock.acquire(blocking=False):
            return  # the holder deletes them when it lets go (it sees ``closed`` after its release)
        try:
            if self._deleted:
                return
            self._deleted = True
            for port in (self._notifier, self._publisher):
                try:
                    port.delete()
                except Exception:
                    pass
            self._service = self._events = None
        finally:
            self._lock.release()


class ShmWriter:
    """A publication's shared-memory writer: its channels, one per subscriber that chose SHM (a
    :class:`~micros_rt.transports.base.TransportWriter`)."""

    protocol = SHM

    def __init__(self, topic: str, *, lossless: bool, latch: bool, queue_size: Optional[int] = None) -> None:
        self.topic = topic
        self.lossless = lossless
        #: the newest this many are kept for a subscriber that falls behind (lossless: the publisher waits)
        self.depth = TRANSIT_DEPTH if lossless or not queue_size else max(1, min(queue_size, TRANSIT_DEPTH))
        self.latch = latch
        self.closed = False
        #: why this publication stopped offering SHM (a channel could not be made or written), or None
        self.failed: Optional[str] = None
        self.dropped = 0
        self.not_taken = 0  # of them: an attached subscriber's channel did not take the sample (KEEP_LAST)
        self.never_attached = 0  # channels closed because no subscriber attached within ATTACH_TIMEOUT
        self._lock = threading.Lock()
        self._channels: Dict[str, ShmChannel] = {}
        self._active: Tuple[ShmChannel, ...] = ()
        self._last: Optional[bytes] = None
        self._largest = 64

    def keep_latched(self, msg: Any) -> None:
        """The last message of a latching publication, for subscribers that come later."""
        body = self.prepare(msg)
        if body is not None:
            self._last = body

    # -- channels (negotiation and housekeeping threads) -------------------------------------------------
    def open_channel(self, subscriber: str, peer_pid: int = 0) -> ShmChannel:
        """A new channel for ``subscriber`` (replacing its old one); raises TransportError in words."""
        try:
            channel = ShmChannel(subscriber, lossless=self.lossless, latch=self.latch, initial_len=self._largest,
                                 depth=self.depth, peer_pid=peer_pid)
        except TransportError as exc:
            raise TransportError(f"topic {self.topic}: cannot create a shared-memory channel: {exc}") from exc
        except Exception as exc:
            raise TransportError(f"topic {self.topic}: cannot create a shared-memory channel: {why_failed(exc)}") \
                from exc
        last = self._last
        if last is not None:
            channel.try_send(last)  # kept as history until the subscriber attaches
        with self._lock:
            old = self._channels.get(subscriber)
            self._channels[subscriber] = channel
            self._active = tuple(self._channels.values())
        if old is not None:
            old.close()
        return channel

    def close_channel(self, channel: ShmChannel) -> None:
        with self._lock:
            if self._channels.get(channel.subscriber) is channel:
                del self._channels[channel.subscriber]
                self._active = tuple(self._channels.values())
        channel.close()

    def channel_for(self, subscriber: str) -> Optional[ShmChannel]:
        """The open channel of ``subscriber`` (its caller id), if any."""
        with self._lock:
            return self._channels.get(subscriber)

    def channels(self) -> Tuple[ShmChannel, ...]:
        return self._active

    def pending_count(self) -> int:
        """Channels whose subscriber's port never attached (yet)."""
        return sum(1 for ch in self._active if not ch.seen and not ch.attached())

    def attached_count(self) -> int:
        return sum(1 for ch in self._active if ch.seen or ch.attached())

    def housekeeping(self, now: float, gone: Callable[[ShmChannel], None]) -> None:
        """Close channels whose subscriber left (its process died, it unsubscribed, or it never attached within
        :data:`ATTACH_TIMEOUT`): ``gone(channel)`` first."""
        if not self._active:
            return
        warn_if_full(now, _log)
        for ch in self._active:
            dead = ch.subscriber_dead()
            if dead:
                cleanup_dead_nodes()  # reclaim its memory and its port in our service
            elif ch.attached():
                if self.latch:
                    ch.update_connections()
                continue
            if dead or ch.seen or now - ch.created > ATTACH_TIMEOUT:
                if not dead and not ch.seen:
                    self.never_attached += 1  # an offer nobody followed (a forged one, or a subscriber that died)
                    _log.warning("micros_rt: topic %s: nothing attached to the shared-memory channel made for %s "
                                 "within %.0f s; closed it (%d such so far)", self.topic, ch.subscriber[:80],
                                 ATTACH_TIMEOUT, self.never_attached)
                gone(ch)
                self.close_channel(ch)

    # -- data (the publishing thread) --------------------------------------------------------------------
    def prepare(self, msg: Any) -> Optional[bytes]:
        if not self._active and not self.latch:
            return None
        buff = io.BytesIO()
        msg.serialize(buff)
        return buff.getvalue()

    def send(self, body: bytes) -> None:
        if self.closed:
            raise TransportError(f"topic {self.topic}: its shared-memory writer is closed (the publication was "
                                 f"unregistered); nothing was sent")
        if self.latch:
            self._last = body
        if len(body) + 16 > self._largest:
            self._largest = len(body) + 16
        for ch in self._active:
            try:
                if ch.try_send(body):
                    continue
                if not ch.attached():
                    continue  # not attached yet (or gone): housekeeping decides
                if not self.lossless:
                    self.dropped += 1  # an attached subscriber that did not take it: counted, never silent
                    self.not_taken += 1
                    continue
                if not send_with_backoff(ch.try_send, body, PUBLISH_BLOCK_TIMEOUT, lambda: ch.closed or self.closed):
                    if ch.closed or self.closed:
                        continue
                    raise PublishTimeoutError(
                        f"topic {self.topic}: publish() stayed blocked for {PUBLISH_BLOCK_TIMEOUT:.1f} s because "
                        f"shared-memory subscriber {ch.subscriber} does not keep up (queue_size=None never drops)")
            except PublishTimeoutError:
                raise
            except Exception as exc:
                if ch.closed or self.closed:
                    continue
                self.dropped += 1
                self._fail(ch, exc)

    def _fail(self, ch: ShmChannel, exc: Exception) -> None:
        """A channel that cannot be written: close it (its subscriber sees the link go and connects again,
        and this publication then declines SHM, so that subscriber gets DDS or TCPROS)."""
        self.failed = f"writing shared memory failed: {exc}" if isinstance(exc, TransportError) else \
            f"writing shared memory failed: {why_failed(exc)}"
        _log.warning("micros_rt: topic %s: %s; subscriber %s is moved off shared memory", self.topic, self.failed,
                     ch.subscriber)
        self.close_channel(ch)

    def close(self) -> None:
        self.closed = True
        with self._lock:
            channels, self._channels, self._active = list(self._channels.values()), {}, ()
        for ch in channels:
            ch.close()


class _Pieces:
    """A message that came in pieces, put together (the subscriber's end)."""

    def __init__(self) -> None:
        self._frame: Optional[bytearray] = None  # header then message, as one frame
        self._seq = 0
        self._filled = 0

    def add(self, piece: bytes) -> Optional[bytearray]:
        """The whole frame once its last piece came, else None; MalformedFrameError for a piece out of place."""
        if len(piece) < _PIECE_HEAD.size:
            raise MalformedFrameError(f"a shared-memory piece of {len(piece)} bytes is shorter than its header")
        raw, source_ns, total, offset = _PIECE_HEAD.unpack_from(piece, 0)
        seq = raw & ~PIECE
        part = memoryview(piece)[_PIECE_HEAD.size:]
        frame = self._frame
        if offset == 0:
            if total > MAX_PIECED:
                raise MalformedFrameError(f"a shared-memory message in pieces says it has {total} bytes, more than "
                                          f"the {MAX_PIECED} micros_rt puts together")
            frame = self._frame = bytearray(16 + total)
            _HEAD.pack_into(frame, 0, seq, source_ns)
            self._seq, self._filled = seq, 0
        elif frame is None or seq != self._seq or offset != self._filled or len(frame) != 16 + total:
            self._frame = None
            raise MalformedFrameError(f"a shared-memory piece of message {seq} at byte {offset} does not follow the "
                                      f"pieces before it")
        end = offset + len(part)
        if end > total:
            self._frame = None
            raise MalformedFrameError(f"a shared-memory piece ends at byte {end} of a {total}-byte message")
        frame[16 + offset:16 + end] = part
        self._filled = end
        if end < total:
            return None
        self._frame = None
        return frame


class ShmLink:
    """The subscriber's end of one channel. Its messages reach the subscription one of two ways:

    - *polled* (:meth:`drain`), by the subscription's delivery thread, which waits on this link's
      ``listener`` itself (:class:`micros_rt.core.delivery.Inbox` with no DDS wait set): one thread wake per
      message, as rospy's receive thread that runs the callbacks;
    - *threaded* (:meth:`start_thread`), where the delivery thread waits on Cyclone's wait set: a thread of
      the link's own (as rospy's per TCPROS connection) decodes and hands each message to ``put``, which may
      wait for room in the subscription's queue (back-pressure to this publisher only).
    """

    def __init__(self, topic: str, channel: str, data_class: Type[genpy.Message], *, header: Dict[str, str],
                 qos: Any, put: Callable[[Any, int, Any], None], on_drop: Callable[[int], None],
                 on_gone: Callable[["ShmLink"], None], peer_pid: int = 0,
                 on_latched: Optional[Callable[[Any], None]] = None) -> None:
        self.topic = topic
        #: a latched publisher's link: each message is also kept there (rospy keeps it on the connection for
        #: callbacks added later), whichever thread drains the link
        self._on_latched = on_latched
        self.peer_pid = peer_pid      # the publisher's process (0: unknown)
        self._peer = PeerProcess(peer_pid)
        self.channel = channel
        self.qos = qos                # the publisher's QoS (lifespan, latency budget), from its answer
        self.closed = False
        self.released = False
        self.malformed = 0
        self._data_class = data_class
        self._header = header
        self._put = put
        self._on_drop = on_drop
        self._on_gone = on_gone
        self._last = 0
        self._pieces = _Pieces()
        try:
            self._service, events = _services(channel, create=False)
            self._subscriber = self._service.subscriber_builder().create()
            self.listener = events.listener_builder().create()
        except Exception as exc:
            raise TransportError(f"topic {topic}: cannot open shared-memory channel {channel}: {why_failed(exc)}") \
                from exc
        self._events = events
        self._thread: Optional[threading.Thread] = None

    def start_thread(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"micros_rt SHM {self.topic}", daemon=True)
        self._thread.start()

    def drain(self, put: Callable[[Any, int, Any], None], limit: int) -> int:
        """Decode and hand over up to ``limit`` waiting messages (any wake-up events are consumed first, so a
        message sent after the last ``receive`` wakes the waiter again). Returns how many were taken."""
        self.listener.try_wait()
        receive = self._subscriber.receive
        data_class, header = self._data_class, self._header
        n = 0
        while n < limit and not self.closed:
            sample = receive()
            if sample is None:
                break
            n += 1
            frame: Any = ctypes.string_at(sample.payload_ptr, _slice_len(sample))  # one copy out of shared memory
            sample.delete()
            try:
                if len(frame) >= 8 and frame[7] & 0x80:  # a piece (the PIECE bit of the little-endian number)
                    frame = self._pieces.add(frame)
                    if frame is None:
                        continue
                seq, source_ns, msg = decode_frame(data_class, frame, self._last)
            except MalformedFrameError as exc:
                self._malformed(exc)
                continue
            last = self._last
            if seq > last + 1:  # sequence numbers start at 1 for the first sample this channel took
                self._on_drop(seq - last - 1)  # overwritten in a KEEP_LAST channel: counted, never silent
            self._last = seq
            msg._connection_header = header
            if self._on_latched is not None:
                self._on_latched(msg)
            put(msg, source_ns, self)
        return n

    def _run(self) -> None:
        iox2 = iceoryx2()
        wait = self.listener.timed_wait
        timeout = iox2.Duration.from_secs_f64(_POLL)
        put = self._put
        try:
            while not self.closed:
                if self.drain(put, 256):
                    continue
                if not wait(timeout) and not self.closed and self.publisher_gone():
                    break
        except Exception as exc:
            if not self.closed:
                _log.warning("micros_rt: topic %s: shared-memory link %s failed (%s); connecting again",
                             self.topic, self.channel, exc)
        finally:
            if self.closed:
                self.release()  # closed meanwhile: the ports are this thread's to let go
            else:
                self._on_gone(self)

    def publisher_gone(self) -> bool:
        """The publisher's process died (its memory is reclaimed then), or its port is gone (it unregistered)."""
        if not self._peer.alive():
            cleanup_dead_nodes()
            return True
        service = self._service
        return service is None or bool(service.dynamic_config.number_of_publishers == 0)

    def notify_gone(self) -> None:
        """Tell the subscription this link's publisher went (it drops the connection)."""
        if not self.closed:
            self._on_gone(self)

    def _malformed(self, exc: Exception) -> None:
        self.malformed += 1
        if self.malformed == 1:
            _log.warning("micros_rt: topic %s: dropped a malformed shared-memory sample from %s: %s. Further ones "
                         "are counted, not logged", self.topic, self._header.get("callerid"), str(exc)[:300])

    def close(self) -> None:
        """Stop taking, without waiting: a threaded link's thread ends within its poll and releases the ports, a
        polled link's are released by the inbox that waits on it, once it stopped waiting. Harmless twice."""
        if self.closed:
            return
        self.closed = True
        self._peer.close()
        thread = self._thread
        if thread is not None and not thread.is_alive():
            self.release()  # else the thread releases the ports when it sees ``closed`` (within its poll)

    def release(self) -> None:
        """Delete the ports (once no wait set holds the listener)."""
        if self.released:
            return
        self.released = True
        for port in (self.listener, self._subscriber):
            try:
                port.delete()
            except Exception:
                pass
        self._service = self._events = None  # the service factories hold the process's iceoryx2 node


def wake_events() -> Tuple[Any, Any]:
    """A (listener, notifier) pair of an event service of its own: how other threads wake a delivery thread
    that waits on an iceoryx2 wait set."""
    iox2 = iceoryx2()
    events = shm_node().service_builder(iox2.ServiceName.new(_channel_name() + "w")).event().create()
    return events.listener_builder().create(), events.notifier_builder().create()
