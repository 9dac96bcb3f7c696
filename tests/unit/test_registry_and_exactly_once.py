"""Unit tests of micros_rt.core.registry.EndpointRegistry and micros_rt.transports.dds.exactly_once.WriterTable (fake endpoints and
readers: no rospy, no DDS)."""

from __future__ import annotations

import sys
import threading
from typing import Any, Dict, List, Optional

import pytest

from micros_rt.transports.dds import exactly_once as _writers
from micros_rt.core.registry import EndpointRegistry
from micros_rt.transports.links import PseudoLink
from micros_rt.transports.dds.exactly_once import DELIVER, DROP, HOLD, Accepted, WriterTable
from micros_rt.transports.base import RemoteWriter
from micros_rt.qos import AdvertiseQoSOptions

# ------------------------------------------------------------------------------------------------ registry


class FakeEndpoint:
    def __init__(self, topic: str, fail_start: bool = False) -> None:
        self.topic = topic
        self.fail_start = fail_start
        self.starts = 0
        self.closes = 0
        self._lock = threading.Lock()

    @property
    def closed(self) -> bool:
        return self.closes > 0

    def start(self) -> None:
        self.starts += 1
        if self.fail_start:
            raise RuntimeError("master unreachable")

    def close(self) -> None:
        with self._lock:
            self.closes += 1


class Factory:
    def __init__(self, topic: str = "/chatter", fail_start: bool = False) -> None:
        self.topic = topic
        self.fail_start = fail_start
        self.made: List[FakeEndpoint] = []
        self._lock = threading.Lock()

    def __call__(self) -> FakeEndpoint:
        ep = FakeEndpoint(self.topic, self.fail_start)
        with self._lock:
            self.made.append(ep)
        return ep


def no_check(ep: FakeEndpoint) -> None:
    pass


def test_get_or_create_and_refcount() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    make = Factory()
    a = reg.acquire("/chatter", make, no_check)
    assert a.starts == 1 and reg.get("/chatter") is a and len(reg) == 1
    b = reg.acquire("/chatter", make, no_check)
    assert b is a and len(make.made) == 1 and a.starts == 1
    reg.release(a)
    assert not a.closed and reg.get("/chatter") is a
    reg.release(a)
    assert a.closes == 1 and reg.get("/chatter") is None and len(reg) == 0 and reg.all() == []
    reg.release(a)  # a stale extra release is a no-op
    assert a.closes == 1


def test_topics_are_independent() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("subscription")
    a = reg.acquire("/a", Factory("/a"), no_check)
    b = reg.acquire("/b", Factory("/b"), no_check)
    assert a is not b and sorted(e.topic for e in reg.all()) == ["/a", "/b"]
    reg.release(a)
    assert a.closed and not b.closed and reg.get("/b") is b


def test_reuse_raising_leaves_counts_unchanged() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    make = Factory()
    a = reg.acquire("/chatter", make, no_check)

    def refuse(ep: FakeEndpoint) -> None:
        raise ValueError("different type")

    for _ in range(3):
        with pytest.raises(ValueError):
            reg.acquire("/chatter", make, refuse)
    assert len(make.made) == 1
    reg.release(a)  # the only real reference: closes now
    assert a.closes == 1 and reg.get("/chatter") is None


def test_reuse_sees_the_existing_endpoint() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    a = reg.acquire("/chatter", Factory(), no_check)
    seen: List[FakeEndpoint] = []
    reg.acquire("/chatter", Factory(), seen.append)
    assert seen == [a]


def test_endpoint_findable_during_start() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    found: List[Optional[FakeEndpoint]] = []

    class Peeking(FakeEndpoint):
        def start(self) -> None:
            found.append(reg.get(self.topic))

    ep = reg.acquire("/chatter", lambda: Peeking("/chatter"), no_check)
    assert found == [ep]


def test_start_raising_withdraws_and_closes() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    bad = Factory(fail_start=True)
    with pytest.raises(RuntimeError, match="master unreachable"):
        reg.acquire("/chatter", bad, no_check)
    (ep,) = bad.made
    assert ep.starts == 1 and ep.closes == 1
    assert reg.get("/chatter") is None and reg.all() == [] and len(reg) == 0
    # the topic is usable again, with refcount starting from one
    good = Factory()
    a = reg.acquire("/chatter", good, no_check)
    assert a is good.made[0]
    reg.release(a)
    assert a.closes == 1 and reg.get("/chatter") is None
    assert ep.closes == 1


def test_start_raising_base_exception_also_withdraws() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")

    class Interrupted(FakeEndpoint):
        def start(self) -> None:
            raise KeyboardInterrupt

    made: List[FakeEndpoint] = []

    def create() -> FakeEndpoint:
        made.append(Interrupted("/chatter"))
        return made[-1]

    with pytest.raises(KeyboardInterrupt):
        reg.acquire("/chatter", create, no_check)
    assert made[0].closes == 1 and reg.get("/chatter") is None


def test_create_raising_leaves_nothing() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")

    def create() -> FakeEndpoint:
        raise TypeError("bad options")

    with pytest.raises(TypeError):
        reg.acquire("/chatter", create, no_check)
    assert reg.get("/chatter") is None and len(reg) == 0


def test_close_all() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("subscription")
    eps = [reg.acquire(f"/t{i}", Factory(f"/t{i}"), no_check) for i in range(5)]
    reg.acquire("/t0", Factory("/t0"), no_check)  # a second reference

    class Broken(FakeEndpoint):
        def close(self) -> None:
            super().close()
            raise OSError("socket gone")

    broken = reg.acquire("/broken", lambda: Broken("/broken"), no_check)
    reg.close_all()
    assert all(ep.closes == 1 for ep in eps) and broken.closes == 1
    assert len(reg) == 0 and reg.all() == [] and reg.get("/t0") is None
    for ep in eps:  # releases after shutdown are no-ops
        reg.release(ep)
    assert all(ep.closes == 1 for ep in eps)
    reg.close_all()
    assert all(ep.closes == 1 for ep in eps)


def test_threaded_acquire_release_race() -> None:
    reg: EndpointRegistry[FakeEndpoint] = EndpointRegistry("publication")
    make = Factory()
    errors: List[str] = []
    barrier = threading.Barrier(8)

    def worker() -> None:
        try:
            barrier.wait(timeout=10)
            for _ in range(2000):
                ep = reg.acquire("/chatter", make, no_check)
                if ep.closed:
                    errors.append("acquire returned a closed endpoint")
                if ep.starts != 1:
                    errors.append(f"endpoint started {ep.starts} times")
                if ep.closed:  # we hold a reference: nobody may close it now
                    errors.append("endpoint closed while referenced")
                reg.release(ep)
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(repr(exc))

    threads = [threading.Thread(target=worker) for _ in range(8)]
    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often: make interleavings likely
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
    finally:
        sys.setswitchinterval(old)
    assert not any(t.is_alive() for t in threads)
    assert errors == []
    assert len(reg) == 0 and reg.get("/chatter") is None
    assert make.made, "nothing created"
    assert [ep.closes for ep in make.made] == [1] * len(make.made)
    assert all(ep.starts == 1 for ep in make.made)


# --------------------------------------------------------------------------------------------- WriterTable

GRAPH = "run1@http://127.0.0.1:11311/"


class FakeReader:
    def __init__(self, writers: Dict[Any, RemoteWriter]) -> None:
        self.writers = writers
        self.calls = 0

    def writer(self, handle: Any) -> Optional[RemoteWriter]:
        self.calls += 1
        return self.writers.get(handle)


def accepted(guid: str) -> Accepted:
    conn = PseudoLink("/chatter", "/listener", "i", "DDS test", peer_guid=guid)
    return Accepted(pub_uri="http://127.0.0.1:1/", node="/talker", latch=False, conn=conn)


def table_with(writers: Dict[Any, RemoteWriter], hold_depth: int = 3) -> "tuple[WriterTable, FakeReader]":
    return WriterTable(GRAPH, hold_depth), FakeReader(writers)


def test_for_handle_creates_once_and_caches() -> None:
    table, reader = table_with({1: RemoteWriter("w1", {"graph": GRAPH})})
    state = table.for_handle(reader, 1)
    assert state is not None and state.guid == "w1" and state.tag == {"graph": GRAPH}
    assert table.for_handle(reader, 1) is state
    assert reader.calls == 1 and len(table) == 1
    assert table.for_handle(reader, 99) is None and len(table) == 1


def test_two_readers_share_one_writer_state() -> None:
    table, volatile = table_with({1: RemoteWriter("w1", {"graph": GRAPH})})
    latched = FakeReader({7: RemoteWriter("w1", {"graph": GRAPH})})
    a = table.for_handle(volatile, 1)
    b = table.for_handle(latched, 7)
    assert a is b and a is not None and len(a.handles) == 2 and len(table) == 1


def test_decide_verdicts() -> None:
    table, reader = table_with({
        1: RemoteWriter("foreign", None),
        2: RemoteWriter("other-graph", {"graph": "run2@http://127.0.0.1:11312/"}),
        3: RemoteWriter("ours", {"graph": GRAPH}),
        4: RemoteWriter("untagged-graph", {}),
    })
    states = [table.for_handle(reader, h) for h in (1, 2, 3, 4)]
    assert all(s is not None for s in states)
    foreign, other, ours, untagged = [s for s in states if s is not None]
    assert table.decide(foreign) == DELIVER
    assert table.decide(other) == DROP
    assert table.decide(untagged) == DROP
    assert table.decide(ours) == HOLD
    table.accept("ours", accepted("ours"), None)
    assert table.decide(ours) == DELIVER
    assert ours.accepted is not None and ours.accepted.conn.peer_guid == "ours"


def test_accept_before_first_sample_creates_state() -> None:
    table, reader = table_with({3: RemoteWriter("ours", {"graph": GRAPH})})
    qos = AdvertiseQoSOptions(latency_budget=0.01)
    early = table.accept("ours", accepted("ours"), qos)
    assert early.qos == qos
    assert table.for_handle(reader, 3) is early
    assert table.decide(early) == DELIVER
    assert [s.guid for s in table.accepted_states()] == ["ours"]


def test_connection_closed_keeps_negotiated_via_qos() -> None:
    table, _ = table_with({})
    acc = accepted("w")
    state = table.accept("w", acc, AdvertiseQoSOptions())
    table.connection_closed(PseudoLink("/chatter", "/l", "i", "x", peer_guid="w"))  # another conn: ignored
    assert state.accepted is acc
    table.connection_closed(acc.conn)
    assert state.accepted is None and state.negotiated  # qos from the answer remains
    assert table.decide(state) == DELIVER
    assert table.accepted_states() == []


def test_connection_closed_without_qos_goes_back_to_hold() -> None:
    table, _ = table_with({})
    acc = accepted("w")
    state = table.accept("w", acc, None)
    table.connection_closed(acc.conn)
    assert not state.negotiated and table.decide(state) == HOLD


def test_hold_bounded_by_depth() -> None:
    table, reader = table_with({3: RemoteWriter("ours", {"graph": GRAPH})}, hold_depth=3)
    state = table.for_handle(reader, 3)
    assert state is not None
    for i in range(10):
        table.hold(state, float(i), bytes([i]), i)
    assert [d for _, d, _ in state.held] == [bytes([7]), bytes([8]), bytes([9])]
    assert table.holding == {state}


def test_releasable_returns_accepted_writers() -> None:
    table, reader = table_with({3: RemoteWriter("a", {"graph": GRAPH}), 4: RemoteWriter("b", {"graph": GRAPH})})
    a, b = table.for_handle(reader, 3), table.for_handle(reader, 4)
    assert a is not None and b is not None
    table.hold(a, 0.0, b"a", None)
    table.hold(b, 0.0, b"b", None)
    assert table.releasable(1.0) == []
    table.accept("a", accepted("a"), None)
    assert table.releasable(1.0) == [a]
    assert list(a.held) == [(0.0, b"a", None)]   # the caller delivers them
    assert table.holding == {b}
    assert table.releasable(1.0) == []


def test_releasable_expires_old_holds(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_writers, "HOLD_SECONDS", 1.0)
    table, reader = table_with({3: RemoteWriter("a", {"graph": GRAPH})}, hold_depth=10)
    a = table.for_handle(reader, 3)
    assert a is not None
    for t in (0.0, 0.5, 1.0, 1.5):
        table.hold(a, t, b"x", t)
    assert table.releasable(1.0) == []
    assert len(a.held) == 4                          # nothing older than 1 s yet
    assert table.releasable(2.2) == []
    assert [t for t, _, _ in a.held] == [1.5]
    assert table.holding == {a}
    assert table.releasable(10.0) == []
    assert not a.held and table.holding == set()


def test_releasable_default_hold_seconds() -> None:
    table, reader = table_with({3: RemoteWriter("a", {"graph": GRAPH})})
    a = table.for_handle(reader, 3)
    assert a is not None
    table.hold(a, 0.0, b"x", None)
    assert table.releasable(_writers.HOLD_SECONDS) == [] and len(a.held) == 1
    assert table.releasable(_writers.HOLD_SECONDS + 0.01) == [] and not a.held


def test_prune_forgets_gone_writers_and_their_handles() -> None:
    table, reader = table_with({
        1: RemoteWriter("gone", {"graph": GRAPH}),
        2: RemoteWriter("matched", {"graph": GRAPH}),
        3: RemoteWriter("connected", {"graph": GRAPH}),
        4: RemoteWriter("holding", {"graph": GRAPH}),
    })
    states = {h: table.for_handle(reader, h) for h in (1, 2, 3, 4)}
    assert all(s is not None for s in states.values())
    table.accept("connected", accepted("connected"), None)
    held = states[4]
    assert held is not None
    table.hold(held, 0.0, b"x", None)
    assert table.prune({"matched"}) == 1
    assert len(table) == 3
    # the handle cache forgot it: the reader is asked again, and a new state is made
    calls = reader.calls
    again = table.for_handle(reader, 1)
    assert reader.calls == calls + 1 and again is not states[1]
    assert table.prune({"matched", "gone"}) == 0
    # a writer that stops holding and is no longer matched goes too
    held.held.clear()
    table.holding.discard(held)
    assert table.prune({"matched"}) == 2          # holding, and gone (again)
    assert len(table) == 2
    assert table.prune(set()) == 1                 # matched is no longer matched; connected stays
    assert [s.guid for s in table.accepted_states()] == ["connected"] and len(table) == 1


def test_prune_removes_from_holding() -> None:
    table, reader = table_with({1: RemoteWriter("w", {"graph": "other"})})
    s = table.for_handle(reader, 1)
    assert s is not None
    table.holding.add(s)       # holding set but its deque already empty
    assert table.prune(set()) == 1
    assert table.holding == set()


# a delegation (DDSAnswer.via): an importing relay's publication names the exporting relay's writers

OTHER = "run9@http://10.0.0.1:11311/"


def test_a_delegation_delivers_that_relays_writers_known_now_and_later_and_ignores_the_delegators_own() -> None:
    table, reader = table_with({
        1: RemoteWriter("exporter", {"graph": OTHER, "relay": "robot_a"}),
        2: RemoteWriter("restarted", {"graph": OTHER, "relay": "robot_a"}),
        3: RemoteWriter("another-relay", {"graph": OTHER, "relay": "robot_c"}),
        4: RemoteWriter("relay-b-own", {"graph": GRAPH, "node": "/relay_b"}),
        5: RemoteWriter("other-local", {"graph": GRAPH, "node": "/talker"}),
    })
    before = table.for_handle(reader, 1)
    assert before is not None and table.decide(before) == DROP  # another graph: not before the answer
    acc = Accepted(pub_uri="http://127.0.0.1:2/", node="/relay_b", latch=False,
                   conn=PseudoLink("/robot_a/chatter", "http://127.0.0.1:2/", "i", "x", peer_guid="exporter"))
    qos = AdvertiseQoSOptions(latency_budget=0.02)
    table.accept("exporter", acc, qos)
    table.delegate("robot_a", acc, qos)
    later = table.for_handle(reader, 2)
    found = {g: table.for_handle(reader, h) for g, h in (("c", 3), ("own", 4), ("local", 5))}
    states = {g: s for g, s in found.items() if s is not None}
    assert later is not None and len(states) == 3
    assert table.decide(before) == DELIVER and before.accepted is acc
    assert table.decide(later) == DELIVER and later.accepted is acc and later.qos == qos
    assert table.decide(states["c"]) == DROP          # only the named relay's writers
    assert table.decide(states["own"]) == DROP        # the delegator's own writer: idle for us, ignored
    assert table.decide(states["local"]) == HOLD      # other publishers of this graph still negotiate
    assert table.is_delegated(acc.conn) and not table.is_delegated(accepted("w").conn)

    table.forget_writer(before)                        # that exporter went: pruned, the link stays
    assert table.prune({"restarted", "another-relay", "relay-b-own", "other-local"}) == 1
    assert len(table) == 4 and table.is_delegated(acc.conn)

    table.connection_closed(acc.conn)                  # the delegating publisher went: nothing of it stays
    assert not table.delegations and later.accepted is None
    new = table.for_handle(FakeReader({6: RemoteWriter("third", {"graph": OTHER, "relay": "robot_a"})}), 6)
    assert new is not None and table.decide(new) == DROP
    assert table.decide(states["own"]) == HOLD      
