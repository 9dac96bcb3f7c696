"""The protocol-order loop of ``requestTopic`` (publisher side), independent of rospy.

The subscriber lists protocols in its preference order; the first one this publisher can serve
wins. A DDS entry is judged by the publication (:func:`micros_rt.negotiation.decide`); other
entries by rospy's protocol handlers. Malformed entries are skipped with a reason, never fatal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, List, Optional, Tuple

from .decide import Verdict
from .messages import DDSAnswer, DDSOffer, MalformedNegotiationError
from .protocol import DDS

__all__ = ["Choice", "choose_protocol"]

#: Judges one offer: (verdict, answer when accepted).
JudgeDDS = Callable[[DDSOffer], Tuple[Verdict, Optional[DDSAnswer]]]


@dataclass
class Choice:
    """What ``requestTopic`` answers: a DDS answer, a rospy protocol entry, or nothing."""

    dds: Optional[DDSAnswer] = None
    entry: Optional[List[Any]] = None
    #: Why DDS (or an entry) was not used, in words, with a stable kind for counting repeats.
    declined: List[Verdict] = field(default_factory=list)


def choose_protocol(protocols: object, *, judge_dds: Optional[JudgeDDS], supports: Callable[[str], bool],
                    subscriber: str, topic: str) -> Choice:
    """Walk ``protocols`` (the subscriber's list, from XML-RPC) in order.

    ``judge_dds`` is None when this topic has no micros_rt publication (a stock rospy publisher in a
    micros_rt process): DDS entries are then skipped silently, as a stock node would.
    """
    choice = Choice()
    if not isinstance(protocols, list):
        choice.declined.append(Verdict(False, "malformed", f"topic {topic}: protocols from {subscriber} are not "
                                                           f"a list"))
        return choice
    for entry in protocols[:16]:
        if not isinstance(entry, list) or not entry or not isinstance(entry[0], str):
            choice.declined.append(Verdict(False, "malformed",
                                           f"topic {topic}: ignored a malformed protocol entry from {subscriber}"))
            continue
        if entry[0] == DDS:
            if judge_dds is None:
                continue
            try:
                offer = DDSOffer.from_xmlrpc(entry[1] if len(entry) > 1 else None, source=f"subscriber {subscriber}")
            except MalformedNegotiationError as exc:
                choice.declined.append(Verdict(False, f"malformed:{exc.field}",
                                               f"topic {topic}: malformed DDS offer from {subscriber} ({exc}); "
                                               f"trying its next protocol"))
                continue
            verdict, answer = judge_dds(offer)
            if verdict.accepted and answer is not None:
                choice.dds = answer
                return choice
            choice.declined.append(verdict)
            continue
        if supports(entry[0]):
            choice.entry = entry
            return choice
    return choice
