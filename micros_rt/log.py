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
import logging.handlers
import queue
import sys
import threading
from typing import Any, Optional, Tuple

__all__ = ["NonBlockingLogger", "nonblocking_logger", "flush"]

_queue: "queue.Queue[logging.LogRecord]" = queue.Queue(maxsize=10_000)
_lock = threading.Lock()
_listener: Optional[logging.handlers.QueueListener] = None
dropped = 0


class _Forward(logging.Handler):
    """On the listener's thread: hand a record to the handlers of the logger it was made for."""

    def handle(self, record: logging.LogRecord) -> bool:
        try:
            logging.getLogger(record.name).handle(record)
        except Exception:  # a broken handler must not end the forwarding
            pass
        return True

    def emit(self, record: logging.LogRecord) -> None:  # pragma: no cover (handle() does the work)
        self.handle(record)


class _Enqueue(logging.handlers.QueueHandler):
    """The standard library's queue handler, never blocking: a full queue drops the record, counted."""

    def enqueue(self, record: logging.LogRecord) -> None:
        global dropped
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            dropped += 1

    def prepare(self, record: logging.LogRecord) -> logging.LogRecord:
        return record  # same process: the real handlers format it, exc_info and all


_enqueue = _Enqueue(_queue)


def _ensure_listener() -> None:
    global _listener
    if _listener is not None:
        return
    with _lock:
        if _listener is None:
            listener = logging.handlers.QueueListener(_queue, _Forward())
            listener.start()
            if listener._thread is not None:  # name it for thread dumps (py-spy, faulthandler)
                listener._thread.name = "micros_rt logging"
            _listener = listener


class NonBlockingLogger:
    """``debug``/``info``/``warning``/``error``/``exception`` like a ``logging.Logger`` named ``name``
    (its level, its handlers, propagation: whatever rospy or the application configured, even after
    ``rospy.init_node`` reconfigures logging), but handled on micros_rt's logging thread. Records carry
    the file, line and function of the call, as ``logging.Logger``'s do."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._target = logging.getLogger(name)

    def _log(self, level: int, msg: str, args: Tuple[Any, ...], exc_info: Any = None) -> None:
        target = self._target
        if not target.isEnabledFor(level):
            return
        if exc_info is True:
            exc_info = sys.exc_info()
        caller = sys._getframe(2)  # the frame that called debug()/warning()/...
        code = caller.f_code
        record = target.makeRecord(self.name, level, code.co_filename, caller.f_lineno, msg, args, exc_info,
                                   code.co_name)
        _ensure_listener()
        _enqueue.enqueue(record)
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
    if _listener is None:
        return
    done = threading.Event()

    def wait() -> None:
        _queue.join()
        done.set()

    threading.Thread(target=wait, daemon=True).start()
    done.wait(timeout)


atexit.register(flush)
