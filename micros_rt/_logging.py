"""Logging that never blocks the thread that logs.

rospy's /rosout handler asks the master for a parameter (``get_param_cached``) when it emits: with the
master unreachable (a link down, a master restarting) a warning logged on a delivery thread blocked it
for the whole outage, and with it every callback and deadline of the topic. micros_rt's loggers put
records on a bounded queue; one thread of their own hands them to the real handlers (console, /rosout,
whatever the application configured). A full queue drops records and counts them.
"""

from __future__ import annotations

import atexit
import logging
import queue
import sys
import threading
from typing import Any, Optional, Tuple

__all__ = ["NonBlockingLogger", "nonblocking_logger", "flush"]

_queue: "queue.Queue[Optional[logging.LogRecord]]" = queue.Queue(maxsize=10_000)
_lock = threading.Lock()
_thread: Optional[threading.Thread] = None
dropped = 0


def _forward() -> None:
    while True:
        record = _queue.get()
        try:
            if record is None:
                return
            logging.getLogger(record.name).handle(record)
        except Exception:  # a broken handler must not end the forwarding
            pass
        finally:
            _queue.task_done()


def _ensure_thread() -> None:
    global _thread
    if _thread is not None and _thread.is_alive():
        return
    with _lock:
        if _thread is None or not _thread.is_alive():
            _thread = threading.Thread(target=_forward, name="micros_rt logging", daemon=True)
            _thread.start()


class NonBlockingLogger:
    """``debug``/``info``/``warning``/``error``/``exception`` like a ``logging.Logger`` named ``name``
    (its level, its handlers, propagation: whatever rospy or the application configured, even after
    ``rospy.init_node`` reconfigures logging), but handled on micros_rt's logging thread."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._target = logging.getLogger(name)

    def _log(self, level: int, msg: str, args: Tuple[Any, ...], exc_info: Any = None) -> None:
        global dropped
        target = self._target
        if not target.isEnabledFor(level):
            return
        if exc_info is True:
            exc_info = sys.exc_info()
        record = target.makeRecord(self.name, level, "(micros_rt)", 0, msg, args, exc_info)
        _ensure_thread()
        try:
            _queue.put_nowait(record)
        except queue.Full:
            dropped += 1

    def debug(self, msg: str, *args: Any, exc_info: Any = None) -> None:
        self._log(logging.DEBUG, msg, args, exc_info)

    def info(self, msg: str, *args: Any, exc_info: Any = None) -> None:
        self._log(logging.INFO, msg, args, exc_info)

    def warning(self, msg: str, *args: Any, exc_info: Any = None) -> None:
        self._log(logging.WARNING, msg, args, exc_info)

    def error(self, msg: str, *args: Any, exc_info: Any = None) -> None:
        self._log(logging.ERROR, msg, args, exc_info)

    def exception(self, msg: str, *args: Any) -> None:
        self._log(logging.ERROR, msg, args, True)


def nonblocking_logger(name: str) -> NonBlockingLogger:
    """A logger for ``name`` (e.g. ``rosout.micros_rt``) that never blocks the caller."""
    return NonBlockingLogger(name)


def flush(timeout: float = 2.0) -> None:
    """Wait (bounded) until queued records are handled: at shutdown, so the last words are not lost."""
    if _thread is None or not _thread.is_alive():
        return
    done = threading.Event()

    def wait() -> None:
        _queue.join()
        done.set()

    threading.Thread(target=wait, daemon=True).start()
    done.wait(timeout)


atexit.register(flush)
