"""Warnings that cannot flood a log: the first of a kind in words, repeats counted and summarised."""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Any, Callable, Hashable, Protocol, Tuple

__all__ = ["RateLimitedLog"]


class _Warns(Protocol):
    def warning(self, msg: str, *args: Any) -> None: ...


class RateLimitedLog:
    """One WARN line the first time a ``key`` (e.g. ``(caller, kind)``) is seen; repeats of that key are
    counted and reported as one line at most every ``interval`` seconds. At most ``max_keys`` keys are
    remembered (the oldest is forgotten first), so a caller inventing new keys cannot grow memory.

    A ``group`` (e.g. the kind of problem) caps the first-time lines of new keys: at most
    ``per_group`` per ``interval``, so callers inventing new names cannot flood the log either; what
    the cap holds back is counted and reported with the group's next line.

    >>> log = RateLimitedLog(logging.getLogger("x"), interval=30.0)
    >>> log.warning(("/attacker", "malformed"), "topic /a: malformed offer")   # logged
    True
    >>> log.warning(("/attacker", "malformed"), "topic /a: malformed offer")   # counted
    False
    """

    def __init__(self, logger: _Warns, *, interval: float = 30.0, max_keys: int = 1024,
                 per_group: int = 5, clock: Callable[[], float] = time.monotonic) -> None:
        self._logger = logger
        self._interval = interval
        self._max_keys = max_keys
        self._clock = clock
        self._lock = threading.Lock()
        # key -> (repeats not yet reported, time of the last line)
        self._seen: "collections.OrderedDict[Hashable, Tuple[int, float]]" = collections.OrderedDict()
        self._per_group = per_group
        # group -> (lines in the current window, window start, held back since the last line)
        self._groups: "collections.OrderedDict[Hashable, Tuple[int, float, int]]" = collections.OrderedDict()
        self.suppressed_total = 0

    def warning(self, key: Hashable, message: str, *, group: Hashable = None) -> bool:
        """Log ``message`` (or count it); True when a line was written."""
        now = self._clock()
        with self._lock:
            entry = self._seen.get(key)
            if entry is None:
                self._seen[key] = (0, now)
                while len(self._seen) > self._max_keys:
                    self._seen.popitem(last=False)
                line = message
                if group is not None:
                    lines, start, held = self._groups.get(group, (0, now, 0))
                    if now - start >= self._interval:
                        lines, start = 0, now
                    if lines >= self._per_group:
                        self._groups[group] = (lines, start, held + 1)
                        self.suppressed_total += 1
                        return False
                    self._groups[group] = (lines + 1, start, 0)
                    while len(self._groups) > self._max_keys:
                        self._groups.popitem(last=False)
                    if held:
                        line = f"{message} ({held} more like this from other callers were not logged)"
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
