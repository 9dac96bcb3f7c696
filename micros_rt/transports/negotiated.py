"""A negotiated transport's two sides: what a publication and a subscription ask of a transport that
``requestTopic`` chooses per publisher and subscriber (shared memory, DDS).

A publication (:mod:`micros_rt.core.publication`) holds one :class:`PublicationSide` per negotiated transport
it may serve, in preference order, and knows nothing else of them: each side judges a subscriber's offer,
keeps its own links (pseudo-connections in rospy's lists, so ``rosnode info`` stays true) and says what
``publish()`` sends through. The publication gives each side a :class:`PublicationHost`: the topic's facts,
where to record a verdict for ``micros-rt topic info``, and a call to make when the side's writer changes.

A subscription (:mod:`micros_rt.core.subscription`) holds one :class:`SubscriptionSide` per negotiated
transport its TransportHints allow: each makes the offer, reads the publisher's answer and makes the link,
which hands messages to the core's delivery thread (one admission path for every transport).

A new negotiated transport is its package with the two sides, plus one entry in the node's registry of
negotiated transports (:data:`micros_rt.core.negotiated.TRANSPORTS`; a plug-in registers through
:func:`micros_rt.extend.register_negotiated_transport`).
"""

from __future__ import annotations

import abc
import dataclasses
import threading
from typing import Any, Callable, Dict, List, Optional, Protocol, Tuple, Type

from ..negotiation import OfferJudge, Verdict
from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions
from .base import PushReader, TransportWriter

__all__ = ["NegotiatedTransport", "PublicationHost", "PublicationSide", "SubscriptionHost", "SubscriptionSide"]


class PublicationHost(Protocol):
    """What a side knows of the publication it serves."""

    topic: str
    data_class: Type[Any]
    queue_size: Optional[int]
    latch: bool
    options: AdvertiseQoSOptions
    #: what this node tags its endpoints with (node name, graph): a transport that carries tags carries these
    tag: Dict[str, str]

    def remember(self, subscriber: str, verdict: Verdict) -> None:
        """Keep the last verdict for ``subscriber`` (its caller id), for ``micros-rt topic info``."""

    def writers_changed(self) -> None:
        """A side's writer appeared, or whether it sends changed: ``publish()`` takes the new set."""

    def latched_message(self) -> Optional[Any]:
        """The last message of a latched topic, published before this side had a writer (None: none)."""


class PublicationSide(abc.ABC):
    """One negotiated transport of one publication (see the module's text)."""

    #: the protocol name in ``requestTopic`` (:data:`micros_rt.negotiation.DDS`, ``SHM``)
    protocol: str = ""
    def __init__(self, host: PublicationHost, *, refusal: Optional[Verdict] = None) -> None:
        self.host = host
        #: the node's profile keeps this topic off this transport: the verdict every subscriber gets, in words
        #: (``micros-rt topic info`` shows it); None: the transport serves when it can
        self.refusal = refusal
        #: what ``publish()`` sends through (None: no writer yet); the publication puts it behind a send
        #: queue when it can say "no room now" and closes it
        self.writer: Optional[TransportWriter] = None

    @abc.abstractmethod
    def negotiated(self, subscriber: str) -> Optional[OfferJudge]:
        """How to parse and judge ``subscriber``'s offer of this protocol; None: not judged here (a
        :attr:`refusal`): the subscriber's entry is skipped as a stock publisher would, with no warning."""

    def open_now(self) -> bool:
        """Open this side's writer now if it waits for a first subscriber (a lazy DDS writer, when ROS 2 appears);
        True when it has one."""
        return self.writer is not None

    def sending(self) -> bool:
        """Whether ``publish()`` sends through :attr:`writer` now (it has one, and someone to serve with it)."""
        return self.writer is not None

    @abc.abstractmethod
    def pseudo_links(self) -> int:
        """This side's links in rospy's connection list (they are not TCPROS links)."""

    @abc.abstractmethod
    def reached(self) -> int:
        """Subscribers of this side that a message published now reaches."""

    def housekeeping(self, now: float) -> None:
        """Drop links whose subscriber went away (the node's housekeeping thread, about once a second)."""

    def dropped(self) -> int:
        """Messages this side dropped by itself (its send queue's drops are the publication's)."""
        return 0

    def refused(self) -> Tuple[int, int]:
        """(offers refused although the rules matched, links closed because their subscriber never came)."""
        return 0, 0

    def delegate(self, source: Callable[[], Any], alive: Callable[[str], bool]) -> None:
        """Serve subscribers with writers of another graph when they can take them (``source()`` names them now,
        ``alive(peer)`` says whether a subscriber's reader still exists); a transport without delegation says so."""
        raise NotImplementedError(f"{self.protocol or type(self).__name__} links cannot be delegated")

    def delegated_links(self) -> int:
        """Subscribers served by the writers of :meth:`delegate`, not by this side's own."""
        return 0

    def link_states(self) -> Optional[Dict[str, bool]]:
        """Per subscriber caller id: whether its link is matched yet (for ``micros-rt topic info``); None when
        this transport's links have no such step (they carry data once made)."""
        return None

    @abc.abstractmethod
    def close(self) -> None:
        """Close the links; the publication closes :attr:`writer` after it (its send queue flushes first)."""


class SubscriptionHost(Protocol):
    """What a side knows of the subscription it connects (the core's delivery thread and its readers)."""

    topic: str
    data_class: Type[Any]
    queue_size: Optional[int]
    depth: Optional[int]
    effective: SubscribeQoSOptions
    options: Optional[SubscribeQoSOptions]
    tag: Dict[str, str]
    lock: threading.Lock
    closed: bool

    def raise_priority(self, qos: Optional[AdvertiseQoSOptions]) -> None:
        """A publisher of ``qos`` connected: the delivery thread runs at its transport priority if higher."""

    def wake(self) -> None:
        """Wake the delivery thread (a link came, data may be there)."""

    def poll_link(self, link: Any, inlet: PushReader) -> bool:
        """For a side whose links the delivery thread can wait on itself (shared memory's): attach ``link``, True
        when the delivery thread does (its messages then go through ``inlet``'s admission); False: the link's own
        thread must hand them to ``inlet``."""


class SubscriptionSide(abc.ABC):
    """One negotiated transport of one subscription: its entry in ``requestTopic``, and the links it makes when
    a publisher accepts it."""

    protocol: str = ""
    #: the transport in a log line ("shared memory")
    words: str = ""

    def __init__(self, host: SubscriptionHost) -> None:
        self.host = host

    @abc.abstractmethod
    def offer(self, held: str) -> Optional[List[Any]]:
        """This transport's entry for ``requestTopic`` (None: not offered now). ``held``: the peer (channel,
        writer) this subscription already reads from the publisher asked, "" when none."""

    @abc.abstractmethod
    def read_answer(self, params: Any, source: str) -> Any:
        """The publisher's answer (raising :class:`~micros_rt.negotiation.MalformedNegotiationError`)."""

    @abc.abstractmethod
    def peer_of(self, answer: Any) -> str:
        """The peer an answer names (a channel, a writer): the same as a link's held one means nothing changed."""

    @abc.abstractmethod
    def connect(self, pub_uri: str, answer: Any) -> Tuple[int, str, int]:
        """Make the link the answer asks for; rospy's ``_connect_topic`` result (1: connected)."""

    def asks_open_first(self, entry: List[Any]) -> bool:
        """Whether the publisher's answer ``entry`` (``[protocol, params]``) asks for this transport's reader
        before it answers (a lazy DDS offer's answer): the subscription then calls :meth:`open_first` and asks
        again."""
        return False

    def open_first(self) -> bool:
        """A publisher asked for this transport's reader before it answers (a lazy DDS offer): open it; True
        when there is one."""
        return False

    def pushed(self) -> Tuple[PushReader, ...]:
        """Readers whose links' threads hand over messages, for the delivery thread to take from."""
        return ()

    # -- a side with pulled readers (DDS), which the delivery thread drains (it asked: ``drain_me``) ------------
    def drain(self, limit: int) -> bool:
        """On the delivery thread: deliver what this side's readers hold (through the host's admission path and
        callbacks), up to about ``limit`` per reader; True when more may be waiting."""
        return False

    def tick(self, now: float) -> None:
        """On the delivery thread, after each drain: deliver what waited for a negotiation's answer."""

    def housekeeping(self, now: float) -> None:
        """On the delivery thread, about once a second (``core.subscription.HOUSEKEEPING_PERIOD``): drop links
        whose publisher went."""

    def pending(self) -> bool:
        """Messages taken from the readers and not yet delivered."""
        return False

    def latched(self) -> List[Any]:
        """The last message of each latching publisher connected over this transport (for a callback added
        later, as rospy replays them)."""
        return []

    def kept_writers(self) -> int:
        """Publishers' writers this side keeps state for now (``statistics().writers``)."""
        return 0

    def has_reader(self) -> bool:
        """Whether this side has a reader of its own open (``micros-rt topic info``)."""
        return False

    def close(self) -> None:
        """Close the links (the delivery thread has stopped)."""


@dataclasses.dataclass(frozen=True)
class NegotiatedTransport:
    """A negotiated transport as a node offers it: its protocol name in ``requestTopic`` and the makers of its two
    sides (what :func:`micros_rt.extend.register_negotiated_transport` takes)."""

    protocol: str
    #: ``(publication, refusal) -> side``; ``refusal``: the node's profile keeps the topic off this transport
    #: (a verdict in words), else None
    publication: Callable[[PublicationHost, Optional[Verdict]], PublicationSide]
    #: ``(subscription) -> side``, made when the subscription's TransportHints allow the protocol
    subscription: Callable[[SubscriptionHost], SubscriptionSide]
