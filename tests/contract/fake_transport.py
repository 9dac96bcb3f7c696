"""An in-memory transport, as httpx's MockTransport: the contract's reference and the core's test double.

One :class:`FakeBus` per test holds topics; :meth:`FakeBus.writer` and :meth:`FakeBus.reader` open the two ends,
which keep the interface of :mod:`micros_rt.transports.base` as every real transport does: ``prepare`` returns
None while no reader is open on the topic, else the message's bytes (genpy's serialization, so a bad value raises
``genpy.SerializationError`` before anything is sent); ``send`` hands those bytes to every reader of the topic;
a reader is a :class:`PushReader` (so the core's subscription can take from it) whose messages are decoded when
they arrive, a malformed payload refused with :class:`FakeWireError` (a :class:`MicrosRtError`). ``enforces``
is whatever the test says (none by default), so a test can check what the core does in its place.
"""

from __future__ import annotations

import io
import threading
from typing import Any, Callable, Dict, FrozenSet, List, Optional, Type

import genpy

from micros_rt.exceptions import MicrosRtError, TransportError
from micros_rt.transports.base import PushReader

__all__ = ["FakeBus", "FakeReader", "FakeWireError", "FakeWriter", "PROTOCOL"]

PROTOCOL = "FAKE"


class FakeWireError(MicrosRtError, ValueError):
    """A payload the fake transport cannot read as the topic's type."""


class FakeReader(PushReader):
    """One subscription's end: decodes each payload when it arrives (as the pushed transports do on their
    I/O thread) and queues the message."""

    def __init__(self, bus: "FakeBus", topic: str, data_class: Type[genpy.Message], depth: Optional[int],
                 wake: Callable[[], None], enforces: FrozenSet[str]) -> None:
        super().__init__(PROTOCOL, depth, wake, blocking=False)
        self.enforces = enforces
        self._bus, self.topic, self.data_class = bus, topic, data_class

    def decode_payload(self, payload: bytes) -> Any:
        msg = self.data_class()
        try:
            msg.deserialize(payload)
        except (genpy.DeserializationError, ValueError, IndexError, UnicodeDecodeError) as exc:
            raise FakeWireError(f"topic {self.topic}: a {len(payload)}-byte payload is not a "
                                f"{self.data_class._type}: {exc or type(exc).__name__}") from exc
        return msg

    def deliver(self, payload: bytes, source_ns: int = 0) -> None:
        self.put(self.decode_payload(payload), source_ns, "fake://bus")

    def close(self) -> None:
        self._bus.detach(self)
        super().close()


class FakeWriter:
    """One publication's end; records what it sent (``sent``)."""

    protocol = PROTOCOL

    def __init__(self, bus: "FakeBus", topic: str) -> None:
        self._bus, self.topic = bus, topic
        self.sent: List[bytes] = []
        self.closed = False

    def prepare(self, msg: Any) -> Optional[bytes]:
        if not self._bus.readers(self.topic):
            return None
        buf = io.BytesIO()
        msg.serialize(buf)  # genpy raises SerializationError on a bad value, before anything is sent
        return buf.getvalue()

    def send(self, prepared: bytes) -> None:
        if self.closed:
            raise TransportError(f"fake transport: the writer of {self.topic} is closed")
        self.sent.append(prepared)
        for reader in self._bus.readers(self.topic):
            reader.deliver(prepared)

    def close(self) -> None:
        self.closed = True


class FakeBus:
    """Topics of one test, in memory."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._readers: Dict[str, List[FakeReader]] = {}

    def writer(self, topic: str) -> FakeWriter:
        return FakeWriter(self, topic)

    def reader(self, topic: str, data_class: Type[genpy.Message], depth: Optional[int] = 100,
               wake: Callable[[], None] = lambda: None, *, enforces: FrozenSet[str] = frozenset()) -> FakeReader:
        reader = FakeReader(self, topic, data_class, depth, wake, enforces)
        with self._lock:
            self._readers.setdefault(topic, []).append(reader)
        return reader

    def readers(self, topic: str) -> List[FakeReader]:
        with self._lock:
            return list(self._readers.get(topic, ()))

    def detach(self, reader: FakeReader) -> None:
        with self._lock:
            if reader in self._readers.get(reader.topic, []):
                self._readers[reader.topic].remove(reader)
