"""Will a publisher's offered QoS and a subscriber's requested QoS work together? And if not, why?

DDS connects a writer and a reader only if, for each "request/offered" (RxO) policy, the offer is
at least as strong as the request; otherwise the pair is silently never matched. micros_rt must never
mean silence: :func:`check_compatibility` predicts the verdict from both sides' micros_rt options
(exchanged during protocol negotiation) so that the negotiation can name the clashing option and fall
back to TCPROS, and :func:`describe_incompatible_policy` turns Cyclone's incompatible-QoS status
(a bare policy id) into the same kind of sentence.

RxO rules as they apply after :mod:`micros_rt.qos.mapping` (offered -> requested):

======================== ==================================== =========================================
DDS policy               micros_rt option(s)                   verdict
======================== ==================================== =========================================
Reliability              using_best_effort_protocol            best-effort pub + reliable sub: CLASH;
                                                               every other combination matches
Durability               latch (pub) / transient_local (sub)   volatile pub + transient-local sub: CLASH
DestinationOrder         ordered_by_sending_timestamp          always matches: writers offer BY_SOURCE
LatencyBudget            latency_budget                        always matches: readers request infinite
Deadline                 deadline                              always matches: not mapped to DDS
TimeBasedFilter          time_filter_duration                  reader-only, no RxO
Lifespan                 msg_valid_period                      writer-only, no RxO
TransportPriority        transport_priority                    writer-only, no RxO
======================== ==================================== =========================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from micros_rt.exceptions import QoSTypeError, QoSValueError
from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions

__all__ = [
    "Compatibility",
    "POLICY_NAMES",
    "check_compatibility",
    "describe_incompatible_policy",
]


@dataclass(frozen=True)
class Compatibility:
    """The verdict of :func:`check_compatibility`.

    ``option`` names the micros_rt option that clashes (``None`` when compatible); ``reason`` says,
    in words a robotics engineer can act on, the topic, both sides' values and which one to change.
    """

    compatible: bool
    option: Optional[str]
    reason: str

    def __bool__(self) -> bool:
        return self.compatible


def check_compatibility(
    offered: AdvertiseQoSOptions,
    requested: SubscribeQoSOptions,
    *,
    topic: str,
    offered_latch: bool = False,
    requested_transient_local: bool = False,
) -> Compatibility:
    """Predict whether a micros_rt publisher and a micros_rt subscriber match over DDS. Pure.

    ``offered_latch`` is the publisher's ``latch``; ``requested_transient_local`` whether the
    subscriber's reader asks for TRANSIENT_LOCAL durability (i.e. for the latched message).

    >>> check_compatibility(AdvertiseQoSOptions(using_best_effort_protocol=True),
    ...                     SubscribeQoSOptions(), topic="/scan").option
    'using_best_effort_protocol'
    """
    if not isinstance(offered, AdvertiseQoSOptions):
        raise QoSTypeError(f"offered={offered!r} is invalid: expected AdvertiseQoSOptions")
    if not isinstance(requested, SubscribeQoSOptions):
        raise QoSTypeError(f"requested={requested!r} is invalid: expected SubscribeQoSOptions")

    # Reliability: BEST_EFFORT < RELIABLE; the offer must be >= the request.
    if offered.using_best_effort_protocol and not requested.using_best_effort_protocol:
        return Compatibility(
            compatible=False,
            option="using_best_effort_protocol",
            reason=(
                f"topic {topic}: the publisher uses best-effort delivery "
                f"(using_best_effort_protocol=True) but the subscriber requires reliable delivery "
                f"(using_best_effort_protocol=False). Set using_best_effort_protocol=True on the "
                f"subscriber, or False on the publisher."
            ),
        )

    # Durability: VOLATILE < TRANSIENT_LOCAL; a transient-local reader needs a latched writer.
    if requested_transient_local and not offered_latch:
        return Compatibility(
            compatible=False,
            option="latch",
            reason=(
                f"topic {topic}: the subscriber expects a latched publisher (transient-local reader) "
                f"but the publisher is not latched (latch=False). Advertise with latch=True, or "
                f"subscribe without asking for the latched message."
            ),
        )

    # DestinationOrder, LatencyBudget, Deadline: compatible by construction of the mapping (see the
    # module docstring); TimeBasedFilter, Lifespan, TransportPriority and History have no RxO rule.
    return Compatibility(
        compatible=True,
        option=None,
        reason=f"topic {topic}: publisher and subscriber QoS are compatible",
    )


#: Cyclone DDS ``dds_qos_policy_id_t`` values (dds/ddsc/dds_public_qosdefs.h, same numbering as the
#: DDS spec's QosPolicyId_t), as reported in ``last_policy_id`` of the requested/offered
#: incompatible-QoS status.
POLICY_NAMES: dict[int, str] = {
    0: "INVALID",
    1: "USERDATA",
    2: "DURABILITY",
    3: "PRESENTATION",
    4: "DEADLINE",
    5: "LATENCYBUDGET",
    6: "OWNERSHIP",
    7: "OWNERSHIPSTRENGTH",
    8: "LIVELINESS",
    9: "TIMEBASEDFILTER",
    10: "PARTITION",
    11: "RELIABILITY",
    12: "DESTINATIONORDER",
    13: "HISTORY",
    14: "RESOURCELIMITS",
    15: "ENTITYFACTORY",
    16: "WRITERDATALIFECYCLE",
    17: "READERDATALIFECYCLE",
    18: "TOPICDATA",
    19: "GROUPDATA",
    20: "TRANSPORTPRIORITY",
    21: "LIFESPAN",
    22: "DURABILITYSERVICE",
    23: "PROPERTY",
    24: "TYPE_CONSISTENCY_ENFORCEMENT",
    25: "DATA_REPRESENTATION",
}
_POLICY_IDS: dict[str, int] = {name.replace("_", ""): pid for pid, name in POLICY_NAMES.items()}

# Per policy: (the micros_rt option that controls it, or None; what to do about it).
_ADVICE: dict[str, tuple[Optional[str], str]] = {
    "RELIABILITY": (
        "using_best_effort_protocol",
        "the publisher is best effort but the subscriber requires reliable delivery; set "
        "using_best_effort_protocol=True on the subscriber, or False on the publisher",
    ),
    "DURABILITY": (
        "latch",
        "the subscriber asks for latched (transient-local) data but the publisher is not latched; "
        "advertise with latch=True, or subscribe without asking for the latched message",
    ),
    "LATENCYBUDGET": (
        "latency_budget",
        "the publisher's latency_budget is larger than the subscriber accepts (plain DDS and ROS 2 "
        "readers accept 0 by default); set latency_budget=0 on the publisher, or raise the peer "
        "reader's latency budget",
    ),
    "DESTINATIONORDER": (
        "ordered_by_sending_timestamp",
        "the subscriber orders by sending timestamp but the publisher only offers reception order "
        "(the default of ROS 2 and plain DDS writers); set ordered_by_sending_timestamp=False on the "
        "subscriber",
    ),
    "DEADLINE": (
        "deadline",
        "the reader requests a DDS deadline that the writer does not offer; micros_rt writers offer "
        "none (micros_rt enforces deadline in its own subscriber), so remove the deadline from the "
        "peer's reader QoS, or use a micros_rt subscriber with deadline=...",
    ),
    "LIVELINESS": (
        None,
        "the peer asks for a liveliness kind or lease stricter than micros_rt offers (AUTOMATIC, "
        "infinite); relax the peer's liveliness QoS",
    ),
    "OWNERSHIP": (
        None,
        "the peer uses EXCLUSIVE ownership, which micros_rt does not use; set the peer to SHARED",
    ),
    "PRESENTATION": (
        None,
        "the peer requests a coherent/ordered presentation scope micros_rt does not offer; relax "
        "the peer's presentation QoS",
    ),
    "PARTITION": (
        None,
        "the two sides are in different DDS partitions; micros_rt uses the default partition",
    ),
    "TYPE_CONSISTENCY_ENFORCEMENT": (
        None,
        "the two sides' message types are not assignable; check both use the same message "
        "definition (ROS 1 md5sum / ROS 2 type)",
    ),
    "DATA_REPRESENTATION": (
        None,
        "the two sides use different data representations (XCDR1 vs XCDR2); micros_rt uses XCDR1 "
        "as ROS 2 does",
    ),
}

_READER_SIDES = ("subscriber", "reader", "requested")
_WRITER_SIDES = ("publisher", "writer", "offered")


def _policy_name(policy_id: int | str) -> str:
    if isinstance(policy_id, bool):
        raise QoSTypeError(f"policy_id={policy_id!r} is invalid: expected a DDS policy id or name")
    if isinstance(policy_id, int):
        return POLICY_NAMES.get(policy_id, f"policy #{policy_id}")
    if isinstance(policy_id, str):
        key = policy_id.strip().upper()
        for affix in ("DDS_", "_QOS_POLICY_ID", "_POLICY_ID", "_QOS_POLICY", "POLICY."):
            key = key.replace(affix, "")
        key = key.replace("_", "").replace(" ", "")
        if key in _POLICY_IDS:
            return POLICY_NAMES[_POLICY_IDS[key]]
        return policy_id
    raise QoSTypeError(
        f"policy_id={policy_id!r} is invalid: expected a DDS policy id (int) or name (str)"
    )


def describe_incompatible_policy(policy_id: int | str, *, topic: str, side: str) -> str:
    """Explain a Cyclone incompatible-QoS event in terms of micros_rt options.

    ``policy_id`` is ``last_policy_id`` of the requested (reader) or offered (writer) incompatible-QoS
    status, or a policy name (``"RELIABILITY"``, ``"DDS_RELIABILITY_QOS_POLICY_ID"``, ...).
    ``side`` says who observed it: ``"subscriber"``/``"reader"`` or ``"publisher"``/``"writer"``.

    >>> describe_incompatible_policy(11, topic="/scan", side="subscriber")  # doctest: +ELLIPSIS
    'topic /scan: the subscriber ... (DDS RELIABILITY, micros_rt option using_best_effort_protocol): ...'
    """
    side_norm = side.strip().lower()
    if side_norm in _READER_SIDES:
        observer, peer = "subscriber", "a publisher"
    elif side_norm in _WRITER_SIDES:
        observer, peer = "publisher", "a subscriber"
    else:
        raise QoSValueError(
            f"side={side!r} is invalid: expected 'subscriber' (or 'reader') or 'publisher' "
            f"(or 'writer')"
        )
    name = _policy_name(policy_id)
    option, advice = _ADVICE.get(
        name,
        (
            None,
            "micros_rt sets this policy the same way on every endpoint, so the peer is probably "
            "not micros_rt; compare its QoS with micros_rt's defaults",
        ),
    )
    what = f"DDS {name}" + (f", micros_rt option {option}" if option else ", no micros_rt option")
    return (
        f"topic {topic}: the {observer} cannot connect to {peer} because their QoS is "
        f"incompatible ({what}): {advice}."
    )
