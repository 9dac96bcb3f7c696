"""What a micros_rt node tells the ``micros-rt`` tools about itself: the ``microsRtInfo`` XML-RPC method.

Every micros_rt node answers ``microsRtInfo(caller_id)`` on its ROS node API (the XML-RPC server that
answers ``getBusInfo``), with ROS's ``[code, status, value]`` triple. ``value`` is a JSON text (XML-RPC
has no null, no infinity and only 32-bit integers): this node's name, pid, wall time (for clock offsets),
DDS domain, and per publication and subscription the topic, type, QoS as plain dicts and every link with
its protocol. A publication also gives the negotiation's last verdict per subscriber that offered DDS
(accepted, or declined with its kind and reason in words). A stock node has no such method: its server
answers with a fault, which is how the tools tell the two apart.

Programs built on micros_rt add a section of their own with :func:`register_section` (the relay's
``"relay"``: what it carries between graphs); the tools read the sections they know and ignore the others.

>>> json.loads(answer("/micros_rt_cli")[2])["node"]                     # doctest: +SKIP
'/talker'
"""

from __future__ import annotations

import dataclasses
import json
import os
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from ..transports.tcpros import patches
from ..negotiation import Verdict

__all__ = ["INFO_METHOD", "INFO_VERSION", "answer", "install", "node_info", "register_section", "unregister_section"]

#: The XML-RPC method name on the node API.
INFO_METHOD = "microsRtInfo"
#: Bumped when the layout of the answer changes incompatibly.
INFO_VERSION = 1
#: The node state the answers describe (set by :func:`install`; the node module owns it)
_node_state: Optional[Callable[[], Any]] = None
#: Extra sections of the answer: name -> callable returning a JSON-able dict (see :func:`register_section`)
_sections: Dict[str, Callable[[], Dict[str, Any]]] = {}
_sections_lock = threading.Lock()
#: The answer's own keys, which no section may take
_CORE_KEYS = frozenset({"version", "node", "pid", "time", "graph", "dds", "profile", "publications", "subscriptions"})


def register_section(name: str, provider: Callable[[], Dict[str, Any]]) -> None:
    """Add ``name: provider()`` to every ``microsRtInfo`` answer of this process (a program's own state, e.g.
    the relay's ``"relay"``). ``provider`` runs on the XML-RPC thread at each call and returns a dict of
    JSON-able values; if it raises, the section is ``{"error": "<what it said>"}``. Registering a name again
    replaces the provider.

    >>> register_section("relay", lambda: {"graph": "robot_a"})             # doctest: +SKIP
    """
    if not name or not isinstance(name, str) or name in _CORE_KEYS:
        raise ValueError(f"microsRtInfo section name {name!r} is empty or one of the answer's own keys "
                         f"({', '.join(sorted(_CORE_KEYS))})")
    with _sections_lock:
        _sections[name] = provider


def unregister_section(name: str) -> None:
    """Remove a section added by :func:`register_section` (no error if there is none)."""
    with _sections_lock:
        _sections.pop(name, None)


def _extra_sections() -> Dict[str, Any]:
    with _sections_lock:
        providers = sorted(_sections.items())
    out: Dict[str, Any] = {}
    for name, provider in providers:
        try:
            out[name] = provider()
        except Exception as exc:  # a program's own bug must not cost the tools the node's core info
            out[name] = {"error": f"{type(exc).__name__}: {exc}"}
    return out


def _verdict_dict(verdict: Verdict) -> Dict[str, Any]:
    return {"accepted": verdict.accepted, "kind": verdict.kind, "reason": verdict.reason}


def _links(topic: str, *, publisher: bool) -> List[Dict[str, Any]]:
    key = "subscriber" if publisher else "publisher"
    return [{key: endpoint, "protocol": transport, "info": info}
            for endpoint, transport, info in patches.bus_info(topic, publisher=publisher)]


def _publication_info(pub: Any) -> Dict[str, Any]:
    with pub.lock:
        verdicts = {sub: _verdict_dict(v) for sub, v in pub.verdicts.items()}
    links = _links(pub.topic, publisher=True)
    for link in links:
        side = pub.sides.get(link["protocol"])
        states = side.link_states() if side is not None else None
        if states is not None:
            link["matched"] = states.get(link["subscriber"], False)
    stats = pub.statistics()
    dds = getattr(pub.sides.get("DDS"), "dds", None)
    return {"topic": pub.topic, "type": pub.data_class._type, "latch": pub.latch, "queue_size": pub.queue_size,
            "qos": pub.options.to_dict(), "dds_topic": dds.dds_topic if dds is not None else None,
            "links": links, "verdicts": verdicts,
            "statistics": {"published": stats.published, "dropped": stats.dropped,
                           "blocked_seconds": stats.blocked_seconds}}


def _subscription_info(sub: Any) -> Dict[str, Any]:
    stats = sub.statistics()
    return {"topic": sub.topic, "type": sub.data_class._type, "queue_size": sub.queue_size,
            "qos": sub.effective.to_dict(), "qos_given": sub.options is not None,
            "hints": list(sub.hints.protocols), "dds_reader": any(side.has_reader() for side in sub.sides.values()),
            "links": _links(sub.topic, publisher=False),
            "statistics": dataclasses.asdict(stats), "latency": sub.stats.summary()}


def node_info() -> Dict[str, Any]:
    """This node's micros_rt view of itself (what ``microsRtInfo`` returns, before JSON)."""
    if _node_state is None:
        raise RuntimeError("micros_rt node info asked before init_node")
    _node = _node_state()
    return {
        "version": INFO_VERSION,
        "node": patches.caller_id(),
        "pid": os.getpid(),
        "time": time.time(),
        "graph": _node.graph,
        "dds": _node.dds_info(),
        "profile": None if _node.profile is None else _node.profile.source,
        "publications": [_publication_info(p) for p in _node.publications.all()],
        "subscriptions": [_subscription_info(s) for s in _node.subscriptions.all()],
        # the profile's links of limited bandwidth and the TCPROS connections paced across each
        "links": [] if _node.pacer is None else _node.pacer.snapshot(),
        **_extra_sections(),
    }


def answer(caller_id: str) -> List[Any]:
    """The XML-RPC answer: ``[1, status, json_text]``, or ``[-1, error, ""]`` (never raises into rospy)."""
    try:
        return [1, "micros_rt node info", json.dumps(node_info(), default=str)]
    except Exception as exc:  # an endpoint closing under us: say so, the caller retries or reports it
        return [-1, f"micros_rt: cannot collect node info: {exc}", ""]


def install(node_state: Callable[[], Any]) -> None:
    """Answer :data:`INFO_METHOD` on this process's node API (idempotent) about ``node_state()``
    (the node's publications, subscriptions, graph, DDS back end and profile)."""
    global _node_state
    _node_state = node_state
    patches.add_node_api_method(INFO_METHOD, answer)
