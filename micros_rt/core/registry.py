"""The one owner of a process's publications and subscriptions.

Get-or-create, reference counts, release and lookup by topic, all under one lock: an endpoint is in
the registry from the moment it can be negotiated with until it is closed, a concurrent ``advertise``
never picks up an endpoint being closed, and an endpoint never removes itself (``close()`` only
releases what it holds). Lookups by the negotiation threads read the dict without the lock (a
single dict read is atomic) so they never wait behind a registration with the master.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable, Dict, Generic, List, Optional, Protocol, TypeVar
from ..log import nonblocking_logger

__all__ = ["Endpoint", "EndpointRegistry"]

_log = nonblocking_logger("rosout.micros_rt")


class Endpoint(Protocol):
    topic: str

    def start(self) -> None:
        """Register with rospy (the master); the endpoint is findable by the negotiation already."""

    def close(self) -> None: ...


E = TypeVar("E", bound=Endpoint)


class EndpointRegistry(Generic[E]):
    """Endpoints of one kind (publications or subscriptions), keyed by resolved topic name."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._lock = threading.RLock()
        self._items: Dict[str, E] = {}
        self._refs: Dict[str, int] = {}

    def acquire(self, topic: str, create: Callable[[], E], reuse: Callable[[E], None]) -> E:
        """The endpoint of ``topic`` with one more reference: ``reuse(existing)`` checks (and may raise),
        or ``create()`` builds a new one, which is made findable and then started (``start()``). A peer may
        call requestTopic the moment rospy registers, so the endpoint is findable first; if ``start``
        raises, it is withdrawn and closed (nothing leaks) and the error propagates."""
        with self._lock:
            found = self._items.get(topic)
            if found is not None:
                reuse(found)
                self._refs[topic] += 1
                return found
            endpoint = create()
            self._items[topic] = endpoint
            try:
                endpoint.start()
            except BaseException:
                del self._items[topic]
                endpoint.close()
                raise
            self._refs[topic] = 1
            return endpoint

    def release(self, endpoint: E) -> None:
        """Drop one reference; the last one removes the endpoint and closes it (under the lock)."""
        with self._lock:
            topic = endpoint.topic
            if self._items.get(topic) is not endpoint:
                return  # already closed (shutdown closed everything)
            self._refs[topic] -= 1
            if self._refs[topic] > 0:
                return
            del self._items[topic]
            del self._refs[topic]
            endpoint.close()

    def get(self, topic: str) -> Optional[E]:
        """The endpoint of ``topic`` (lock-free read, for negotiation threads)."""
        return self._items.get(topic)

    def all(self) -> List[E]:
        with self._lock:
            return list(self._items.values())

    def close_all(self) -> None:
        """Close every endpoint (shutdown); errors are logged, the others still close."""
        with self._lock:
            items = list(self._items.values())
            self._items.clear()
            self._refs.clear()
            for endpoint in items:
                try:
                    endpoint.close()
                except Exception:
                    _log.exception("micros_rt: closing the %s of %s failed", self.kind, endpoint.topic)

    def __len__(self) -> int:
        return len(self._items)
