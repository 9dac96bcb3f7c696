"""Warnings that cannot flood a log: the first of a kind in words, repeats counted and summarised."""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Callable, Hashable, Tuple

__all__ = ["RateLimitedLog"]


class RateLimitedLog:
    """One WARN line the first time a ``key`` (e.g. ``(caller, kind)``) is seen; repeats of that key are
    counted and reported as one line at most every ``interval`` seconds. At most ``max_keys`` keys are
    remembered (the oldest is forgotten first), so a caller inventing new keys cannot grow memory.

    >>> log = RateLimitedLog(logging.getLogger("x"), interval=30.0)
    >>> log.warning(("/attacker", "malformed"), "topic /a: malformed offer")   # logged
    True
    >>> log.warning(("/attacker", "malformed"), "topic /a: malformed offer")   # counted
    False
    """

    def __init__(self, logger: logging.Logger, *, interval: float = 30.0, max_keys: int = 1024,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._logger = logger
        self._interval = interval
        self._max_keys = max_keys
        self._clock = clock
        self._lock = threading.Lock()
        # key -> (repeats not yet reported, time of the last line)
        self._seen: "collections.OrderedDict[Hashable, Tuple[int, float]]" = collections.OrderedDict()
        self.suppressed_total = 0

    def warning(self, key: Hashable, message: str) -> bool:
        """Log ``message`` (or count it); True when a line was written."""
        now = self._clock()
        with self._lock:
            entry = self._seen.get(key)
            if entry is None:
                self._seen[key] = (0, now)
                while len(self._seen) > self._max_keys:
                    self._seen.popitem(last=False)
                line = message
            else:
                repeats, last = entry
                repeats += 1
                self.suppressed_total += 1
                if now - last < self._interval:
                    self._seen[key] = (repeats, last)
                    return False
                self._seen[key] = (0, now)
                line = f"{message} ({repeats} more like this in the last {now - last:.0f} s)"
        self._logger.warning("micros_rt: %s", line)
        return True
