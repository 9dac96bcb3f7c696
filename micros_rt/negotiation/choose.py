"""The protocol-order loop of ``requestTopic`` (publisher side), independent of rospy.

The subscriber lists protocols in its preference order; the first one this publisher can serve wins, as
rospy's ``protocol_handlers`` loop does. Negotiated transports (shared memory and DDS, and any a plug-in
registers) are registered by name (:class:`OfferJudge`: how to read that protocol's offer, and the publication's
judge; each transport's offer and judge live in its own package); other
entries go to rospy's protocol handlers (``supports``). Malformed entries are skipped with a reason,
never fatal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, List, Mapping, Optional, Tuple

from .decide import Verdict
from .messages import MalformedNegotiationError
from .protocol import negotiated_protocols

__all__ = ["Choice", "OfferJudge", "choose_protocol"]


@dataclass(frozen=True)
class OfferJudge:
    """How one publication reads and judges one subscriber's offer of a negotiated transport in ``requestTopic``:
    ``parse(params, source)`` reads the offer (raising :class:`MalformedNegotiationError`), ``judge(offer)`` is the
    publication's verdict and answer (an object with ``to_xmlrpc()``, the entry sent back). Not to be confused
    with :class:`micros_rt.extend.NegotiatedTransport`, the transport a node offers (a name and its two sides)."""

    parse: Callable[[Any, str], Any]
    judge: Callable[[Any], Tuple[Verdict, Any]]


@dataclass
class Choice:
    """What ``requestTopic`` answers: a negotiated transport's answer, a rospy protocol entry, or nothing."""

    #: the negotiated transport chosen and its answer (``to_xmlrpc()`` is the entry to send back)
    protocol: str = ""
    answer: Any = None
    entry: Optional[List[Any]] = None
    #: Why a negotiated transport (or an entry) was not used, in words, with a stable kind for counting repeats.
    declined: List[Verdict] = field(default_factory=list)

    def answer_for(self, protocol: str) -> Any:
        """The answer when ``protocol`` was chosen, else None."""
        return self.answer if self.protocol == protocol else None


def choose_protocol(protocols: object, *, negotiated: Mapping[str, OfferJudge],
                    supports: Callable[[str], bool], subscriber: str, topic: str) -> Choice:
    """Walk ``protocols`` (the subscriber's list, from XML-RPC) in order.

    ``negotiated`` holds the transports this topic's publication can negotiate, by protocol name; an
    entry of a negotiated transport the publication does not have (a stock rospy publisher in a micros_rt
    process: none) is skipped silently, as a stock node would.
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
        name = entry[0]
        transport = negotiated.get(name)
        if transport is not None:
            try:
                offer = transport.parse(entry[1] if len(entry) > 1 else None, f"subscriber {subscriber}")
            except MalformedNegotiationError as exc:
                choice.declined.append(Verdict(False, f"malformed:{exc.field}",
                                               f"topic {topic}: malformed {name} offer from {subscriber} ({exc}); "
                                               f"trying its next protocol"))
                continue
            verdict, answer = transport.judge(offer)
            if verdict.accepted and answer is not None:
                choice.protocol, choice.answer = name, answer
                return choice
            choice.declined.append(verdict)
            continue
        if name in negotiated_protocols():
            continue  # no such transport here (a stock publisher): skipped, as a stock node would
        if supports(name):
            choice.entry = entry
            return choice
    return choice
