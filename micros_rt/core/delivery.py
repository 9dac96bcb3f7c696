"""What wakes a subscription's delivery thread: DDS data (a Cyclone wait set), shared-memory data (an iceoryx2
wait set), TCPROS messages and connects, close. User callbacks run on that thread, never on a Cyclone or socket
thread that they could block."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional
from ..cyclone import import_cyclonedds

if TYPE_CHECKING:
    from ..transports.dds.participant import DDSParticipant
    from ..transports.shm.channel import ShmLink


__all__ = ["Inbox"]


class Inbox:
    """A Cyclone wait set when DDS is in use (back-end readers attach their conditions); else an iceoryx2 wait
    set once a shared-memory link is there (the delivery thread waits on the links' listeners itself: one
    thread wake per message); else an Event."""

    def __init__(self, participant: Optional[DDSParticipant]) -> None:
        self._event = threading.Event()
        self._guard_up = False
        self.waitset: Any = None
        self.guard: Any = None
        if participant is not None:
            import_cyclonedds()
            from cyclonedds.core import GuardCondition, WaitSet

            self.waitset = WaitSet(participant.dp)
            self.guard = GuardCondition(participant.dp)
            self.waitset.attach(self.guard)
        # shared memory (iceoryx2): made by the delivery thread when the first link comes
        self._lock = threading.Lock()
        self._pending: List["ShmLink"] = []
        self.links: Dict["ShmLink", Any] = {}     # polled link -> its wait-set guard
        self._iox: Any = None                     # (wait set, wake listener, wake notifier, wake guard, duration)
        self._notify: Optional[Callable[[], Any]] = None

    def attach(self, reader: Any) -> None:
        """Wake on ``reader``'s native condition when it has one (DDS); other back ends call :meth:`wake`."""
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.attach(condition)

    def detach(self, reader: Any) -> None:
        condition = getattr(reader, "condition", None)
        if condition is not None and self.waitset is not None:
            self.waitset.detach(condition)

    def attach_shm(self, link: "ShmLink") -> bool:
        """Let the delivery thread wait on ``link`` itself (True), which it can when it waits on no Cyclone wait
        set; False: the link must wake it from a thread of its own."""
        if self.waitset is not None:
            return False
        with self._lock:
            self._pending.append(link)
        self.wake()
        return True

    def wake(self) -> None:
        if self.guard is not None:
            # trigger first, flag second: wait() may then spin once until it sees the flag,
            # but never leaves the guard raised with the flag down (a busy loop)
            self.guard.set(True)
            self._guard_up = True
            return
        notify = self._notify
        if notify is not None:
            notify()
        else:
            self._event.set()

    def wait(self, timeout: float) -> None:
        if self.waitset is not None:
            self.waitset.wait(int(max(timeout, 0.0) * 1e9))
            if self._guard_up:  # reset only when raised: one C call less per DDS sample
                self._guard_up = False
                self.guard.set(False)
        elif self._iox is not None or self._pending:
            self._wait_shm(timeout)
        else:
            self._event.wait(timeout)
            self._event.clear()

    def _wait_shm(self, timeout: float) -> None:
        """On the delivery thread: attach new links, let go of closed ones, then wait on all of them."""
        from ..transports.shm.channel import wake_events
        from ..transports.shm.host import iceoryx2, wait_set

        iox2 = iceoryx2()
        if self._iox is None:
            waitset = wait_set()
            listener, notifier = wake_events()
            guard = waitset.attach_notification(listener)
            self._iox = (waitset, listener, notifier, guard, iox2.Duration.from_secs_f64)
            self._notify = notifier.notify
            if self._event.is_set():  # a wake that came as an Event, before the notifier was there
                self._event.clear()
                return
        waitset, listener, _notifier, _guard, duration = self._iox
        with self._lock:
            pending, self._pending = self._pending, []
        for link in pending:
            if not link.closed:
                self.links[link] = waitset.attach_notification(link.listener)
        for link in [k for k in self.links if k.closed]:
            del self.links[link]  # the guard goes: detached
            link.release()
        if pending:
            return  # the new links may hold data already
        waitset.wait_and_process_with_timeout(duration(max(timeout, 0.0)))
        listener.try_wait()

    def close(self) -> None:
        """Delete the wait sets and guard (after the delivery thread stopped waiting on them)."""
        from ..transports.dds.participant import delete_entity

        for entity in (self.waitset, self.guard):
            if entity is not None:
                delete_entity(entity)
        self.waitset = self.guard = None
        links, self.links = list(self.links), {}
        with self._lock:
            links += self._pending
            self._pending = []
        self._notify = None
        iox, self._iox = self._iox, None
        for link in links:
            link.close()
            link.release()
        if iox is not None:
            waitset, listener, notifier, guard, _duration = iox
            del guard, waitset  # detached before the listener goes
            for port in (listener, notifier):
                try:
                    port.delete()
                except Exception:
                    pass
