"""Which per-topic rule applies to a topic: the one matcher for every profile section (QoS publishers and
subscribers, the MQTT back end's topics; the relay's will use it too). Pure.

A key is a resolved topic name, an :mod:`fnmatch` glob (``*``, ``?``, ``[...]``; ``*`` also matches ``/``)
or a ``^...$`` regular expression. An exact name beats any pattern; among matching patterns the longest
key wins; equally long ones: the first in the file.

>>> rules = [(TopicPattern.parse("/cam/*"), "glob"), (TopicPattern.parse("/cam/image"), "exact"),
...          (TopicPattern.parse("^/cam/.*$"), "regex")]
>>> best_match(rules, "/cam/image"), best_match(rules, "/cam/info"), best_match(rules, "/other")
('exact', 'regex', None)
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass
from typing import Iterable, Optional, Pattern, Tuple, TypeVar

__all__ = ["TopicPattern", "best_match"]

_GLOB_CHARS = frozenset("*?[")
T = TypeVar("T")


@dataclass(frozen=True)
class TopicPattern:
    """One rule's key, parsed once."""

    key: str
    regex: Optional[Pattern[str]] = None

    @classmethod
    def parse(cls, key: str) -> "TopicPattern":
        """Raises ``re.error`` for a ``^...$`` key that is not a regular expression."""
        if key.startswith("^") and key.endswith("$"):
            return cls(key, re.compile(key))
        return cls(key)

    @property
    def exact(self) -> bool:
        return self.regex is None and not any(c in _GLOB_CHARS for c in self.key)

    def matches(self, topic: str) -> bool:
        if self.regex is not None:
            return self.regex.fullmatch(topic) is not None
        if self.exact:
            return topic == self.key
        return fnmatch.fnmatchcase(topic, self.key)


def best_match(rules: Iterable[Tuple[TopicPattern, T]], topic: str) -> Optional[T]:
    """The value of the rule that applies to ``topic`` (rules in file order), or None."""
    best: Optional[Tuple[bool, int, int]] = None
    found: Optional[T] = None
    for order, (pattern, value) in enumerate(rules):
        if pattern.matches(topic):
            rank = (not pattern.exact, -len(pattern.key), order)
            if best is None or rank < best:
                best, found = rank, value
    return found
