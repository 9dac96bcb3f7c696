"""What wakes a subscription's delivery thread when no transport's wait set does: an Event (TCPROS messages and
connects, a program's reader, close). A transport with a native wait set brings its own inbox of the same shape
(:class:`micros_rt.transports.base.Inbox`: Cyclone's for DDS readers, iceoryx2's for shared-memory links). User
callbacks run on the delivery thread, never on a transport's or a socket's thread that they could block."""

from __future__ import annotations

from typing import Any, Dict

from ..transports.base import Wakeup

__all__ = ["EventInbox"]


class EventInbox:
    """A wake-up flag: every reader and link wakes the delivery thread itself."""

    wakes_on_readers = False

    def __init__(self) -> None:
        self._event = Wakeup()
        self.links: Dict[Any, Any] = {}

    def attach(self, reader: Any) -> None:
        pass

    def detach(self, reader: Any) -> None:
        pass

    def attach_link(self, link: Any) -> bool:
        return False

    def wake(self) -> None:
        self._event.set()

    def wait(self, timeout: float) -> None:
        self._event.wait(timeout)

    def close(self) -> None:
        pass
