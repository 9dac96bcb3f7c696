"""A delivery thread's inbox for shared memory: an Event until the first link comes, then an iceoryx2 wait set on
the links' listeners and a wake event of its own (one thread wake per message, no thread per link). The delivery
thread drains the links it waits on itself (:attr:`ShmInbox.links`)."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional

from ..base import Wakeup
from .channel import wake_events
from .host import iceoryx2, wait_set

if TYPE_CHECKING:
    from .channel import ShmLink

__all__ = ["ShmInbox"]


class ShmInbox:
    """See the module's text."""

    wakes_on_readers = False

    def __init__(self) -> None:
        self._event = Wakeup()
        self._lock = threading.Lock()
        self._pending: List["ShmLink"] = []
        self.links: Dict["ShmLink", Any] = {}     # polled link -> its wait-set guard
        self._iox: Any = None                     # (wait set, wake listener, wake notifier, wake guard, duration)
        self._notify: Optional[Callable[[], Any]] = None

    def attach(self, reader: Any) -> None:
        pass

    def detach(self, reader: Any) -> None:
        pass

    def attach_link(self, link: Any) -> bool:
        with self._lock:
            self._pending.append(link)
        self.wake()
        return True

    def wake(self) -> None:
        notify = self._notify
        if notify is not None:
            notify()
        else:
            self._event.set()

    def wait(self, timeout: float) -> None:
        if self._iox is not None or self._pending:
            self._wait_links(timeout)
        else:
            self._event.wait(timeout)

    def _wait_links(self, timeout: float) -> None:
        """On the delivery thread: attach new links, let go of closed ones, then wait on all of them."""
        iox = self._iox
        if iox is None:
            waitset = wait_set()
            listener, notifier = wake_events()
            guard = waitset.attach_notification(listener)
            iox = self._iox = (waitset, listener, notifier, guard, iceoryx2().Duration.from_secs_f64)
            self._notify = notifier.notify
            if self._event.is_set():  # a wake that came before the notifier was there
                self._event.wait(0)
                return
        waitset, listener, _notifier, _guard, duration = iox
        if self._pending:
            with self._lock:
                pending, self._pending = self._pending, []
            for link in pending:
                if not link.closed:
                    self.links[link] = waitset.attach_notification(link.listener)
            return  # the new links may hold data already
        for link in self.links:
            if link.closed:
                self._release_closed()
                break
        waitset.wait_and_process_with_timeout(duration(max(timeout, 0.0)))
        listener.try_wait()

    def _release_closed(self) -> None:
        for link in [k for k in self.links if k.closed]:
            del self.links[link]  # the guard goes: detached
            link.release()

    def close(self) -> None:
        """Delete the wait set and the links' listeners (after the delivery thread stopped waiting on them)."""
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

