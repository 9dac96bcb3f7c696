"""What wakes a subscription's delivery thread: DDS data (a Cyclone wait set), TCPROS messages and
connects (a guard condition), close. User callbacks run on that thread, never on a Cyclone or socket
thread that they could block."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any, Optional

if TYPE_CHECKING:
    from ..transports.dds.participant import DDSParticipant


__all__ = ["Inbox"]


class Inbox:
    """A wait set when DDS is in use (back-end readers attach their conditions), else an Event."""

    def __init__(self, participant: Optional[DDSParticipant]) -> None:
        self._event = threading.Event()
        self._guard_up = False
        self.waitset: Any = None
        self.guard: Any = None
        if participant is not None:
            from cyclonedds.core import GuardCondition, WaitSet

            self.waitset = WaitSet(participant.dp)
            self.guard = GuardCondition(participant.dp)
            self.waitset.attach(self.guard)

    def attach(self, reader: Any) -> None:
        """Wake on ``reader``'s native condition when it has one (DDS); other back ends call :meth:`wake`."""
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.attach(condition)

    def detach(self, reader: Any) -> None:
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.detach(condition)

    def wake(self) -> None:
        if self.guard is not None:
            # trigger first, flag second: wait() may then spin once until it sees the flag,
            # but never leaves the guard raised with the flag down (a busy loop)
            self.guard.set(True)
            self._guard_up = True
        else:
            self._event.set()

    def wait(self, timeout: float) -> None:
        if self.waitset is not None:
            self.waitset.wait(int(max(timeout, 0.0) * 1e9))
            if self._guard_up:  # reset only when raised: one C call less per DDS sample
                self._guard_up = False
                self.guard.set(False)
        else:
            self._event.wait(timeout)
            self._event.clear()

    def close(self) -> None:
        """Delete the wait set and guard (after the delivery thread stopped waiting on them)."""
        from ..transports.dds.participant import delete_entity

        for entity in (self.waitset, self.guard):
            if entity is not None:
                delete_entity(entity)
        self.waitset = self.guard = None
