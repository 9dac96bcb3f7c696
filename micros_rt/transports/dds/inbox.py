"""A delivery thread's inbox on a Cyclone wait set: the subscription's DDS readers attach their read conditions, so
a sample wakes the thread without a wake call per sample; other transports' readers raise its guard condition."""

from __future__ import annotations

from typing import Any, Dict

from ...cyclone import import_cyclonedds
from .participant import DDSParticipant, delete_entity

__all__ = ["CycloneInbox"]


class CycloneInbox:
    """A Cyclone wait set and a guard condition (see the module's text)."""

    wakes_on_readers = True

    def __init__(self, participant: DDSParticipant) -> None:
        import_cyclonedds()
        from cyclonedds.core import GuardCondition, WaitSet

        self._guard_up = False
        self.links: Dict[Any, Any] = {}  # it waits on no shared-memory link (they wake it from their threads)
        self.waitset: Any = WaitSet(participant.dp)
        self.guard: Any = GuardCondition(participant.dp)
        self.waitset.attach(self.guard)

    def attach(self, reader: Any) -> None:
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.attach(condition)

    def detach(self, reader: Any) -> None:
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.detach(condition)

    def attach_link(self, link: Any) -> bool:
        return False

    def wake(self) -> None:
        guard = self.guard
        if guard is not None:
            # trigger first, flag second: wait() may then spin once until it sees the flag,
            # but never leaves the guard raised with the flag down (a busy loop)
            guard.set(True)
            self._guard_up = True

    def wait(self, timeout: float) -> None:
        waitset = self.waitset
        if waitset is None:
            return
        waitset.wait(int(max(timeout, 0.0) * 1e9))
        if self._guard_up:  # reset only when raised: one C call less per DDS sample
            self._guard_up = False
            self.guard.set(False)

    def close(self) -> None:
        """Delete the wait set and guard (after the delivery thread stopped waiting on them)."""
        for entity in (self.waitset, self.guard):
            if entity is not None:
                delete_entity(entity)
        self.waitset = self.guard = None
