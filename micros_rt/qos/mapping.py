"""Mapping of micros_rt QoS options (plus rospy's queue_size/latch) onto Cyclone DDS ``Qos`` objects.

Pure functions: no entity is created here. Which policy each option maps to is the QoS catalogue's
(``dds_policy`` in :data:`micros_rt.qos.options.OPTIONS`); how a value becomes that policy is here:

============================== =====================================================================
option                         DDS policy
============================== =====================================================================
queue_size                     writer History KEEP_LAST(queue_size); 0/None (rospy's synchronous,
                               lossless publishing) -> KEEP_ALL, reliable writes block up to
                               :data:`PUBLISH_BLOCK_TIMEOUT` (back-pressure). Readers keep all:
                               the subscriber keeps the newest queue_size itself and counts drops
latch / transient_local        Durability TRANSIENT_LOCAL (depth >= 1), else VOLATILE
transport_priority             TransportPriority(level 0..6)
latency_budget                 LatencyBudget 0 on the writer (readers request infinite, see below);
                               micros_rt batches the writer's samples into shared datagrams and
                               sends them within half the budget, at most 2 ms
                               (:mod:`micros_rt.transports.dds.batching`):
                               Cyclone's own LatencyBudget > 0 mode hands every sample to a send
                               thread, which measured slower than not batching at all
using_best_effort_protocol     Reliability BEST_EFFORT / RELIABLE
msg_valid_period               Lifespan (absent when infinite, which is the DDS default)
ordered_by_sending_timestamp   DestinationOrder BY_SOURCE / BY_RECEPTION on the reader; writers
                               always offer BY_SOURCE
time_filter_duration           TimeBasedFilter (absent when 0)
deadline                       not mapped: enforced by the micros_rt subscriber itself
============================== =====================================================================

Why the asymmetries: DDS matches a writer and a reader only if every "request/offered" policy
offered by the writer is at least as strong as the reader's request (Reliability, Durability,
Deadline, LatencyBudget, DestinationOrder, ...); otherwise the pair is silently never connected.
Writers therefore offer the strongest DestinationOrder, and readers request the weakest LatencyBudget
and no Deadline, so that these micros_rt options never make two micros_rt endpoints incompatible.
Cyclone 11 does enforce LatencyBudget RxO (verified: a 10 ms writer and a default reader do not match).
"""

from __future__ import annotations

import functools
import math

from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from cyclonedds.qos import Qos

# cyclonedds is imported inside the functions: ``import micros_rt`` stays light, and micros_rt.init_node
# loads Cyclone in the background while rospy starts (spawn-to-first-message time).

#: DDS_INFINITY: the largest duration, "forever".
_DDS_INFINITY = 0x7FFFFFFFFFFFFFFF

from micros_rt.exceptions import QoSTypeError, QoSValueError
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions, options_of
from ..cyclone import import_cyclonedds

__all__ = [
    "PUBLISH_BLOCK_TIMEOUT",
    "RELIABLE_MAX_BLOCKING_TIME",
    "WRITER_MAX_BLOCKING_TIME",
    "UNBOUNDED_QUEUE_DEPTH",
    "duration_ns",
    "is_lossless",
    "history_depth",
    "plain_reader_qos",
    "plain_writer_qos",
    "reader_qos",
    "writer_qos",
]

#: History depth used for rospy's queue_size 0 / None ("unbounded"). Not KEEP_ALL: a reliable KEEP_ALL
#: writer blocks ``publish()`` when a slow reader has not acknowledged (back-pressure that ROS 1 code
#: never expects) and lets memory grow without bound; 1000 samples is rospy's own common "big queue".
UNBOUNDED_QUEUE_DEPTH: int = 1000

#: Seconds a reliable KEEP_LAST writer's blocking ``send`` waits while Cyclone has more unacknowledged
#: data than the writer's window. Not Cyclone's max_blocking_time (that is 0, :data:`WRITER_MAX_BLOCKING_TIME`):
#: micros_rt waits in Python, and ``publish()`` of a KEEP_LAST topic does not wait at all (its send queue keeps
#: the newest ``queue_size`` and sends them when there is room, :mod:`micros_rt.core.send_queue`).
RELIABLE_MAX_BLOCKING_TIME: float = 1.0

#: Cyclone's Reliability max_blocking_time for micros_rt writers: 0, never wait inside ``dds_write``.
#: Cyclone waits there holding Python's GIL, so a topic with a slow link stalled every thread of the
#: process (a 1 kHz control topic ran at a third of its rate beside a throttled camera).
WRITER_MAX_BLOCKING_TIME: float = 0.0

#: Seconds ``publish()`` on a lossless topic (``queue_size=None``/0) may block while a reliable
#: subscriber is behind before it raises :class:`micros_rt.PublishTimeoutError` naming the topic.
PUBLISH_BLOCK_TIMEOUT: float = 5.0


def is_lossless(queue_size: int | None) -> bool:
    """rospy's ``queue_size=None`` (or 0): synchronous publishing, nothing dropped."""
    return queue_size is None or queue_size == 0


def duration_ns(seconds: float) -> int:
    """Float seconds (``math.inf`` = forever) -> DDS nanoseconds (``DDS_INFINITY`` for forever)."""
    if math.isinf(seconds):
        return _DDS_INFINITY
    # round(): 0.005 * 1e9 is 5000000.000000001 in binary floating point.
    return int(round(seconds * 1e9))


def history_depth(queue_size: int | None) -> int:
    """KEEP_LAST depth for a rospy ``queue_size``: itself when > 0, else :data:`UNBOUNDED_QUEUE_DEPTH`.

    rospy reads 0 and None as "no limit"; DDS needs a bound (see :data:`UNBOUNDED_QUEUE_DEPTH`).
    """
    if queue_size is None:
        return UNBOUNDED_QUEUE_DEPTH
    if isinstance(queue_size, bool) or not isinstance(queue_size, int):
        raise QoSTypeError(
            f"queue_size={queue_size!r} is invalid: expected an int >= 0 (0 or None = unbounded)"
        )
    if queue_size < 0:
        raise QoSValueError(
            f"queue_size={queue_size!r} is invalid: expected an int >= 0 (0 or None = unbounded)"
        )
    return queue_size if queue_size > 0 else UNBOUNDED_QUEUE_DEPTH


def _reliability(best_effort: bool, blocking: float = RELIABLE_MAX_BLOCKING_TIME) -> object:
    import_cyclonedds()
    from cyclonedds.qos import Policy

    if best_effort:
        return Policy.Reliability.BestEffort
    return Policy.Reliability.Reliable(max_blocking_time=duration_ns(blocking))


def _user_data(user_data: bytes) -> list[object]:
    import_cyclonedds()
    from cyclonedds.qos import Policy

    if not isinstance(user_data, (bytes, bytearray, memoryview)):
        raise QoSTypeError(f"user_data={user_data!r} is invalid: expected bytes")
    data = bytes(user_data)
    # Empty USER_DATA is the DDS default; leaving it out keeps the Qos equal to a peer's plain one.
    return [Policy.Userdata(data=data)] if data else []


@functools.lru_cache(maxsize=None)
def _policy_builders() -> dict[str, Callable[[Any, str], list[object]]]:
    """How a value of an option becomes DDS policies, per DDS policy the catalogue names (``dds_policy``); made
    once, on first use (cyclonedds is imported only by a node that uses DDS)."""
    import_cyclonedds()
    from cyclonedds.qos import Policy

    return {
        # writers never wait inside Cyclone (WRITER_MAX_BLOCKING_TIME); readers' value is Cyclone's default
        "Reliability": lambda best_effort, side: [_reliability(
            best_effort, WRITER_MAX_BLOCKING_TIME if side == "advertise" else RELIABLE_MAX_BLOCKING_TIME)],
        "TransportPriority": lambda level, _side: [Policy.TransportPriority(priority=int(level))],
        # 0, not the budget: Cyclone's budget > 0 mode hands every sample to a send thread; micros_rt batches
        # within the budget itself (transports/dds/batching.py)
        "LatencyBudget": lambda _budget, _side: [Policy.LatencyBudget(budget=0)],
        "Lifespan": lambda seconds, _side: [] if math.isinf(seconds) else [
            Policy.Lifespan(lifespan=duration_ns(seconds))],
        "DestinationOrder": lambda by_source, _side: [
            Policy.DestinationOrder.BySourceTimestamp if by_source else Policy.DestinationOrder.ByReceptionTimestamp],
        "TimeBasedFilter": lambda seconds, _side: [
            Policy.TimeBasedFilter(filter_time=duration_ns(seconds))] if seconds > 0.0 else [],
    }


def _option_policies(options: AdvertiseQoSOptions | SubscribeQoSOptions, side: str) -> list[object]:
    """The DDS policies of every option of ``options`` that maps to one (the catalogue's ``dds_policy``)."""
    builders = _policy_builders()
    out: list[object] = []
    for option in options_of(side):
        if option.dds_policy is not None:
            out.extend(builders[option.dds_policy](getattr(options, option.name), side))
    return out


def writer_qos(
    options: AdvertiseQoSOptions, *, queue_size: int | None, latch: bool, user_data: bytes = b""
) -> Qos:
    """DataWriter Qos for a publisher advertised with ``options``, ``queue_size`` and ``latch``.

    - Reliability RELIABLE (max_blocking_time 0: :data:`WRITER_MAX_BLOCKING_TIME`; the waiting for room,
      bounded by :data:`PUBLISH_BLOCK_TIMEOUT` when lossless, happens in Python) or BEST_EFFORT per
      ``using_best_effort_protocol``.
    - History KEEP_LAST(queue_size) (always >= 1, which a latched writer needs), or KEEP_ALL when
      ``queue_size`` is None/0 (:func:`is_lossless`): nothing dropped, ``publish()`` blocks instead.
    - Durability TRANSIENT_LOCAL if ``latch`` (late joiners get the last message) else VOLATILE.
    - Lifespan(msg_valid_period) only when finite.
    - LatencyBudget 0 (micros_rt batches within ``latency_budget`` itself, see
      :mod:`micros_rt.transports.dds.batching`) and TransportPriority(level) always.
    - DestinationOrder BY_SOURCE_TIMESTAMP always: the strongest offer, compatible with readers of
      either kind (the subscriber's ``ordered_by_sending_timestamp`` decides).
    - Userdata(user_data) when non-empty (e.g. the graph tag).

    >>> from cyclonedds.qos import Policy
    >>> writer_qos(AdvertiseQoSOptions(), queue_size=10, latch=False)[Policy.History]
    Policy.History.KeepLast(depth=10)
    """
    import_cyclonedds()
    from cyclonedds.qos import Policy, Qos

    if not isinstance(options, AdvertiseQoSOptions):
        raise QoSTypeError(f"options={options!r} is invalid: expected AdvertiseQoSOptions")
    if not isinstance(latch, bool):
        raise QoSTypeError(f"latch={latch!r} is invalid: expected True or False")
    history_depth(queue_size)  # validates
    lossless = is_lossless(queue_size)
    policies: list[object] = [
        Policy.History.KeepAll if lossless else Policy.History.KeepLast(depth=history_depth(queue_size)),
        Policy.Durability.TransientLocal if latch else Policy.Durability.Volatile,
        Policy.DestinationOrder.BySourceTimestamp,  # the strongest offer: readers of either kind match
    ]
    policies.extend(_option_policies(options, "advertise"))
    policies.extend(_user_data(user_data))
    return Qos(*policies)


def reader_qos(
    options: SubscribeQoSOptions,
    *,
    queue_size: int | None,
    transient_local: bool = False,
    user_data: bytes = b"",
) -> Qos:
    """DataReader Qos for a subscriber with ``options`` and ``queue_size``.

    - Reliability RELIABLE or BEST_EFFORT per ``using_best_effort_protocol`` (a best-effort reader
      matches writers of both kinds).
    - History KEEP_ALL: the subscriber takes samples as they come and keeps the newest ``queue_size``
      itself, so every drop is counted (Cyclone does not report KEEP_LAST overwrites).
      ``queue_size`` is still validated.
    - Durability TRANSIENT_LOCAL if ``transient_local`` (to receive a latched publisher's last message;
      such a reader only matches latched writers) else VOLATILE.
    - DestinationOrder BY_SOURCE_TIMESTAMP if ``ordered_by_sending_timestamp`` else BY_RECEPTION.
    - TimeBasedFilter(time_filter_duration) when > 0 (Cyclone filters per instance, by source time).
    - LatencyBudget INFINITE: DDS requires offered <= requested, so any finite request would make
      publishers with a larger ``latency_budget`` silently incompatible. Latency budgets are a
      publisher's hint; micros_rt measures them, it does not match on them.
    - Deadline deliberately NOT set: a finite requested deadline makes every writer that offers no
      deadline (all micros_rt and default ROS 2 writers) incompatible. The micros_rt subscriber
      enforces ``deadline``/``deadline_cb`` itself with a timer, on DDS and TCPROS links alike.
    - Userdata(user_data) when non-empty.
    """
    import_cyclonedds()
    from cyclonedds.qos import Policy, Qos

    if not isinstance(options, SubscribeQoSOptions):
        raise QoSTypeError(f"options={options!r} is invalid: expected SubscribeQoSOptions")
    if not isinstance(transient_local, bool):
        raise QoSTypeError(f"transient_local={transient_local!r} is invalid: expected True or False")
    history_depth(queue_size)  # validates
    policies: list[object] = [
        Policy.History.KeepAll,
        Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
        Policy.LatencyBudget(budget=duration_ns(math.inf)),
    ]
    policies.extend(_option_policies(options, "subscribe"))
    policies.extend(_user_data(user_data))
    return Qos(*policies)


def plain_writer_qos(*, queue_size: int | None, latch: bool, user_data: bytes = b"") -> Qos:
    """Writer Qos for ``advertise()`` without QoS options: :func:`writer_qos` with the defaults."""
    return writer_qos(AdvertiseQoSOptions(), queue_size=queue_size, latch=latch, user_data=user_data)


def plain_reader_qos(
    *, queue_size: int | None, transient_local: bool = False, user_data: bytes = b""
) -> Qos:
    """Reader Qos for ``subscribe()`` without QoS options.

    Like the defaults except DestinationOrder BY_RECEPTION_TIMESTAMP: that is ROS 1's behaviour (every
    message in arrival order, whatever the sender's clock) and it matches ROS 2 writers, which offer
    BY_RECEPTION by default (a BY_SOURCE reader would not match them).
    """
    return reader_qos(
        SubscribeQoSOptions(ordered_by_sending_timestamp=False),
        queue_size=queue_size,
        transient_local=transient_local,
        user_data=user_data,
    )
