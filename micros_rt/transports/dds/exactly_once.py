"""Exactly-once delivery: which DDS writers' samples a subscription delivers, holds or drops, and the
state it keeps per writer (one object, dropped when the writer goes).

A micros_rt reader hears every micros_rt writer of the topic on the DDS domain, but delivers only
samples of writers whose publisher accepted DDS in the negotiation with *this* node; the others reach
it over TCPROS, or not at all (another ROS graph on the same domain). Samples that arrive before the
negotiation's answer are held, bounded, and delivered first when it arrives. Writers without a
micros_rt tag (ROS 2 nodes) are delivered as they are.

A publisher that republishes another graph's topic (an importing relay) may answer with a *delegation*
instead (``DDSAnswer.via``): the writers of that graph's relay (tag ``relay=<via>``) already reach this
reader, so they are delivered as if from the publisher, straight, and every writer of that relay that comes
later (a restarted exporter) too; the publisher's own writer, idle for this subscriber, is ignored.
"""

from __future__ import annotations

import collections
import enum
import threading
from dataclasses import dataclass, field
from typing import Any, Deque, Dict, List, Optional, Set, Tuple

from ..links import PseudoLink
from ..base import RemoteWriter
from ...qos import AdvertiseQoSOptions, ClockSkewCheck

__all__ = ["Accepted", "Admission", "WriterState", "WriterTable", "DELIVER", "HOLD", "DROP", "HOLD_SECONDS"]


class Admission(enum.IntEnum):
    """What a subscription does with a DDS writer's sample (:meth:`WriterTable.decide`)."""

    DELIVER = 0   # negotiated with this node, or a ROS 2 writer
    HOLD = 1      # a micros_rt writer whose negotiation has not answered yet
    DROP = 2      # another graph's, or a delegating publisher's own writer


DELIVER, HOLD, DROP = Admission.DELIVER, Admission.HOLD, Admission.DROP
#: How long samples of a not-yet-negotiated writer wait for the negotiation's answer.
HOLD_SECONDS = 5.0


@dataclass
class Accepted:
    """The negotiated publisher behind a writer."""

    pub_uri: str
    node: str
    latch: bool
    conn: PseudoLink


@dataclass
class Delegation:
    """A publisher's answer that names another graph's relay writers (``via``) instead of its own."""

    accepted: Accepted
    qos: Optional[AdvertiseQoSOptions]


@dataclass(eq=False)
class WriterState:
    """Everything a subscription knows of one DDS writer."""

    guid: str
    tag: Optional[Dict[str, str]]
    accepted: Optional[Accepted] = None
    qos: Optional[AdvertiseQoSOptions] = None  # the publisher's QoS (budget, lifespan), from the answer
    held: Deque[Tuple[float, bytes, Any]] = field(default_factory=collections.deque)
    last_ts: int = -1                          # dedupe between the volatile and the latched reader
    header_seq: int = 0                        # Header.seq is not on the DDS wire: counted per writer
    conn_header: Optional[Dict[str, str]] = None
    latched: Any = None                        # a latching publisher's last message, for callbacks added later
    skew: ClockSkewCheck = field(default_factory=ClockSkewCheck)
    malformed: int = 0
    handles: Set[Tuple[int, Any]] = field(default_factory=set)  # (reader id, back-end handle)

    @property
    def negotiated(self) -> bool:
        # a writer negotiated before and now gone still has the samples it sent us delivered
        return self.accepted is not None or self.qos is not None


class WriterTable:
    """Per-writer state of one subscription, and the exactly-once decision."""

    def __init__(self, graph: str, hold_depth: int) -> None:
        self.graph = graph
        self.hold_depth = hold_depth
        self._lock = threading.Lock()
        self._states: Dict[str, WriterState] = {}
        self._by_handle: Dict[Tuple[int, Any], WriterState] = {}
        self.holding: Set[WriterState] = set()
        # relay graph name (``via``) -> the delegating publisher's link; its node names, whose own writers
        # this subscription then ignores
        self.delegations: Dict[str, Delegation] = {}
        self._delegating_nodes: Set[str] = set()

    def for_handle(self, reader: Any, handle: Any) -> Optional[WriterState]:
        """The state of the writer behind a sample (created on its first sample)."""
        key = (id(reader), handle)
        state = self._by_handle.get(key)
        if state is not None:
            return state
        remote: Optional[RemoteWriter] = reader.writer(handle)
        if remote is None:
            return None
        with self._lock:
            state = self._states.get(remote.guid)
            if state is None:
                state = self._states[remote.guid] = WriterState(remote.guid, remote.tag)
                self._apply_delegation(state)
            state.handles.add(key)
            self._by_handle[key] = state
        return state

    def decide(self, state: WriterState) -> Admission:
        if state.tag is None or state.negotiated:
            return DELIVER
        if state.tag.get("graph") != self.graph:
            return DROP  # another ROS graph on the same DDS domain
        if state.tag.get("node") in self._delegating_nodes:
            return DROP  # a publisher that delegated to another graph's relay: its own writer serves others
        return HOLD

    def _apply_delegation(self, state: WriterState) -> None:
        tag = state.tag
        if tag is None or state.accepted is not None or tag.get("graph") == self.graph:
            return
        delegation = self.delegations.get(tag.get("relay", ""))
        if delegation is not None:
            state.accepted, state.qos = delegation.accepted, delegation.qos

    def delegate(self, via: str, accepted: Accepted, qos: Optional[AdvertiseQoSOptions]) -> None:
        """Deliver the writers of graph ``via``'s relay as from ``accepted``'s publisher, those known now
        and those that come later."""
        with self._lock:
            self.delegations[via] = Delegation(accepted, qos)
            self._delegations_changed()
            for state in self._states.values():
                if state.tag is not None and state.tag.get("relay") == via:
                    self._apply_delegation(state)

    def _delegations_changed(self) -> None:
        self._delegating_nodes = {d.accepted.node for d in self.delegations.values()}

    def is_delegated(self, conn: PseudoLink) -> bool:
        return any(d.accepted.conn is conn for d in self.delegations.values())

    def hold(self, state: WriterState, now: float, data: bytes, info: Any) -> None:
        if len(state.held) >= self.hold_depth:
            state.held.popleft()
        state.held.append((now, data, info))
        self.holding.add(state)

    def accept(self, writer: str, accepted: Accepted, qos: Optional[AdvertiseQoSOptions]) -> WriterState:
        with self._lock:
            state = self._states.get(writer)
            if state is None:
                state = self._states[writer] = WriterState(writer, {"graph": self.graph})
            state.accepted = accepted
            if qos is not None:
                state.qos = qos
            state.conn_header = None
            return state

    def connection_closed(self, conn: PseudoLink) -> None:
        with self._lock:
            for via in [v for v, d in self.delegations.items() if d.accepted.conn is conn]:
                del self.delegations[via]
                self._delegations_changed()
            for state in self._states.values():
                if state.accepted is not None and state.accepted.conn is conn:
                    state.accepted = None

    def forget_writer(self, state: WriterState) -> None:
        """A delegated writer went (its relay restarted): prune it; the link stays for its successor."""
        with self._lock:
            state.accepted = None

    def releasable(self, now: float) -> List[WriterState]:
        """Writers holding samples whose negotiation finished; expire holds older than HOLD_SECONDS."""
        ready = []
        for state in list(self.holding):
            if state.negotiated:
                ready.append(state)
                self.holding.discard(state)
                continue
            while state.held and now - state.held[0][0] > HOLD_SECONDS:
                state.held.popleft()
            if not state.held:
                self.holding.discard(state)
        return ready

    def accepted_states(self) -> List[WriterState]:
        with self._lock:
            return [s for s in self._states.values() if s.accepted is not None]

    def prune(self, matched: Set[str]) -> int:
        """Forget writers that are gone (not matched, not connected, nothing held); returns how many."""
        with self._lock:
            gone = [s for g, s in self._states.items() if g not in matched and s.accepted is None and not s.held]
            for state in gone:
                del self._states[state.guid]
                for key in state.handles:
                    self._by_handle.pop(key, None)
                self.holding.discard(state)
        return len(gone)

    def __len__(self) -> int:
        return len(self._states)
