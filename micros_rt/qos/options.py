"""QoS option values of micros_rt: what a publisher offers and what a subscriber requests.

These mirror micROS RT's ``AdvertiseQoSOptions`` / ``SubscribeQoSOptions`` structs (same members,
same order, same defaults) as immutable, validated values. Derive variants with
:func:`dataclasses.replace`::

    >>> opts = AdvertiseQoSOptions(transport_priority="high", latency_budget=0.005)
    >>> dataclasses.replace(opts, using_best_effort_protocol=True).using_best_effort_protocol
    True

Durations are float seconds inside: ``0.0`` is ``DURATION_MIN`` and ``math.inf`` is ``DURATION_MAX``.
Strings exist only at the edges (:meth:`TransportPriority.parse`, ``to_dict``/``from_dict`` for XML-RPC
and YAML profiles).
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Optional

from micros_rt.exceptions import QoSTypeError, QoSValueError, UnsupportedQoSError
from micros_rt.qos.enforcement import Admission, Lifespan, SourceOrder, TimeFilter

__all__ = [
    "DURATION_MAX",
    "DURATION_MIN",
    "AdvertiseQoSOptions",
    "DeadlineMissedCallback",
    "SubscribeQoSOptions",
    "TransportPriority",
    "priority_dscp",
    "priority_socket_priority",
    "priority_tos",
    "to_seconds",
]

#: The shortest duration: "as soon as possible" / "no filter" (micROS ``ros::DURATION_MIN``).
DURATION_MIN: float = 0.0
#: The longest duration: "never expires" / "no deadline" (micROS ``ros::DURATION_MAX``).
DURATION_MAX: float = math.inf

#: Called with the subscriber's deadline-missed information when no message arrived in time.
DeadlineMissedCallback = Callable[[Any], None]

_DURATION_EXPECTED = (
    "expected a duration >= 0 in seconds (float/int), rospy.Duration or datetime.timedelta"
)


class TransportPriority(enum.IntEnum):
    """The seven transport priority levels of micROS RT (``ros::ExtremelyLow`` .. ``ros::ExtremelyHigh``).

    The integer value is what goes into the DDS TransportPriority policy. On the wire micros_rt marks
    its sockets with :func:`priority_dscp` / :func:`priority_socket_priority` (Cyclone itself does not).

    >>> TransportPriority.parse("ExtremelyLow") is TransportPriority.EXTREMELY_LOW
    True
    """

    EXTREMELY_LOW = 0
    VERY_LOW = 1
    LOW = 2
    NORMAL = 3
    HIGH = 4
    VERY_HIGH = 5
    EXTREMELY_HIGH = 6

    @classmethod
    def parse(cls, value: str | int | TransportPriority) -> TransportPriority:
        """Return the level named or numbered by ``value``.

        Accepts a member, an int 0..6, or a name in any case and spelling: ``"HIGH"``, ``"high"``,
        ``"ExtremelyLow"``, ``"extremely_low"``, ``"extremely-low"``, ``"ros::High"``.
        Raises :class:`QoSValueError` (or :class:`QoSTypeError`) naming the allowed values.
        """
        if isinstance(value, cls):
            return value
        if isinstance(value, bool):
            # bool is an int subclass; True would silently mean VERY_LOW.
            raise QoSTypeError(
                f"transport_priority={value!r} is invalid: expected one of {_priority_allowed()}"
            )
        if isinstance(value, int):
            try:
                return cls(value)
            except ValueError:
                raise QoSValueError(
                    f"transport_priority={value!r} is invalid: expected one of {_priority_allowed()}"
                ) from None
        if isinstance(value, str):
            key = _normalise_priority_name(value)
            for member in cls:
                if member.name.replace("_", "") == key:
                    return member
            raise QoSValueError(
                f"transport_priority={value!r} is invalid: expected one of {_priority_allowed()}"
            )
        raise QoSTypeError(
            f"transport_priority={value!r} is invalid: expected one of {_priority_allowed()} "
            f"(got {type(value).__name__})"
        )


def _normalise_priority_name(text: str) -> str:
    text = text.strip()
    if text.lower().startswith("ros::"):
        text = text[5:]
    # "ExtremelyLow", "extremely_low", "EXTREMELY-LOW", "extremely low" all become "EXTREMELYLOW".
    return re.sub(r"[\s_\-]", "", text).upper()


def _priority_allowed() -> str:
    names = ", ".join(m.name for m in TransportPriority)
    return f"{names} (any case, e.g. 'high' or 'ExtremelyLow') or an int 0..6"


# DSCP per level. NORMAL stays unmarked (DF/CS0) so that default traffic looks like any other ROS
# traffic. Below normal we follow the "scavenger < bulk < best effort" ordering of RFC 4594 / RFC 8622
# as deployed (LE=1, CS1=8, AF11=10 all get less than DF); above normal RFC 4594's
# AF41 (low-latency interactive) < CS5 (signalling) < EF (expedited, telephony-grade).
_DSCP: dict[TransportPriority, int] = {
    TransportPriority.EXTREMELY_LOW: 1,  # LE, lower effort (RFC 8622)
    TransportPriority.VERY_LOW: 8,  # CS1, low-priority data / scavenger (RFC 4594)
    TransportPriority.LOW: 10,  # AF11, high-throughput bulk data (RFC 4594)
    TransportPriority.NORMAL: 0,  # DF / CS0, default forwarding
    TransportPriority.HIGH: 34,  # AF41
    TransportPriority.VERY_HIGH: 40,  # CS5
    TransportPriority.EXTREMELY_HIGH: 46,  # EF, expedited forwarding (RFC 3246)
}

# Linux SO_PRIORITY; 0..6 are allowed without CAP_NET_ADMIN. Values are TC_PRIO_* so that the classic
# pfifo_fast priomap puts low levels in band 2, NORMAL/HIGH in band 1 and VERY_HIGH and above in band 0
# (priority 5 is skipped: that priomap sends it to band 2).
_SO_PRIORITY: dict[TransportPriority, int] = {
    TransportPriority.EXTREMELY_LOW: 1,  # TC_PRIO_FILLER
    TransportPriority.VERY_LOW: 2,  # TC_PRIO_BULK
    TransportPriority.LOW: 3,
    TransportPriority.NORMAL: 0,  # TC_PRIO_BESTEFFORT, the kernel's default
    TransportPriority.HIGH: 4,  # TC_PRIO_INTERACTIVE_BULK
    TransportPriority.VERY_HIGH: 6,  # TC_PRIO_INTERACTIVE
    TransportPriority.EXTREMELY_HIGH: 6,  # 7 (TC_PRIO_CONTROL) would need CAP_NET_ADMIN
}


def priority_dscp(p: TransportPriority) -> int:
    """DSCP codepoint (0..63) that micros_rt puts on the IP packets of a link with priority ``p``.

    ============== ===== =============================
    level          DSCP  per-hop behaviour
    ============== ===== =============================
    EXTREMELY_LOW  1     LE (lower effort)
    VERY_LOW       8     CS1 (scavenger)
    LOW            10    AF11 (bulk data)
    NORMAL         0     DF (unmarked, default)
    HIGH           34    AF41
    VERY_HIGH      40    CS5
    EXTREMELY_HIGH 46    EF
    ============== ===== =============================
    """
    return _DSCP[TransportPriority.parse(p)]


def priority_tos(p: TransportPriority) -> int:
    """The IP_TOS byte for ``p``: its DSCP shifted past the two ECN bits (``priority_dscp(p) << 2``)."""
    return priority_dscp(p) << 2


def priority_socket_priority(p: TransportPriority) -> int:
    """Linux ``SO_PRIORITY`` (0..6, settable without CAP_NET_ADMIN) for ``p``; NORMAL is 0.

    Set it *after* ``IP_TOS``: on Linux, setting IP_TOS also overwrites the socket priority.
    """
    return _SO_PRIORITY[TransportPriority.parse(p)]


def to_seconds(value: object, option_name: str) -> float:
    """Return ``value`` as float seconds, or raise an error naming ``option_name``.

    Accepts int/float seconds (``math.inf`` = forever), :class:`datetime.timedelta` and anything
    with a ``to_sec()`` method (``rospy.Duration``, duck-typed so that this package needs no rospy).
    Rejects bools (:class:`QoSTypeError`), negative values and NaN (:class:`QoSValueError`).

    >>> to_seconds(datetime.timedelta(milliseconds=5), "latency_budget")
    0.005
    """
    seconds: float
    if isinstance(value, bool):
        raise QoSTypeError(f"{option_name}={value!r} is invalid: {_DURATION_EXPECTED}, not a bool")
    if isinstance(value, (int, float)):
        seconds = float(value)
    elif isinstance(value, datetime.timedelta):
        seconds = value.total_seconds()
    elif callable(getattr(value, "to_sec", None)):
        raw = value.to_sec()  # type: ignore[attr-defined]
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise QoSTypeError(
                f"{option_name}={value!r} is invalid: its to_sec() returned {raw!r}; {_DURATION_EXPECTED}"
            )
        seconds = float(raw)
    else:
        raise QoSTypeError(
            f"{option_name}={value!r} is invalid: {_DURATION_EXPECTED} (got {type(value).__name__})"
        )
    if math.isnan(seconds) or seconds < 0.0:
        raise QoSValueError(f"{option_name}={seconds!r} is invalid: {_DURATION_EXPECTED}")
    return seconds


def _check_bool(value: object, option_name: str) -> bool:
    # Only real bools: 0/1 or "false" from a config file must not be silently truthy/falsy here.
    if not isinstance(value, bool):
        raise QoSTypeError(
            f"{option_name}={value!r} is invalid: expected True or False (got {type(value).__name__})"
        )
    return value


def _refuse_data_centric_update() -> None:
    raise UnsupportedQoSError(
        "data_centric_update=True is not supported: ROS 1 messages carry no key fields, so DDS cannot "
        "form keyed instances for them (micROS RT never supported it either). For last-value semantics "
        "use queue_size=1 on both sides, or a latched topic (latch=True) so late joiners get the last "
        "message."
    )


def _encode_duration(seconds: float) -> float | str:
    # XML-RPC has no infinity (and Python's xmlrpc refuses to marshal inf), so forever travels as "inf".
    return "inf" if math.isinf(seconds) else seconds


def _decode_duration(value: object, option_name: str) -> float:
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("inf", "+inf", "infinity", "+infinity", "duration_max", "max"):
            return math.inf
        if text in ("duration_min", "min"):
            return 0.0
        try:
            number = float(text)
        except ValueError:
            raise QoSValueError(
                f"{option_name}={value!r} is invalid: {_DURATION_EXPECTED}, or 'inf'"
            ) from None
        return to_seconds(number, option_name)
    return to_seconds(value, option_name)


def _check_keys(cls_name: str, known: tuple[str, ...], d: Mapping[str, Any], source: str) -> None:
    if not isinstance(d, Mapping):
        raise QoSTypeError(
            f"{cls_name} from {source}: expected a mapping of option names to values, "
            f"got {type(d).__name__}"
        )
    unknown = [k for k in d if k not in known]
    if unknown:
        hint = ""
        if "deadline_cb" in unknown:
            hint = " (deadline_cb is a Python callable: pass it in code, it cannot travel as data)"
        raise QoSValueError(
            f"{cls_name} from {source}: unknown option(s) {', '.join(repr(k) for k in unknown)}{hint}; "
            f"known options: {', '.join(known)}"
        )


#: Names of the enforcers: what a micros_rt subscription (or publication) applies itself, on every transport,
#: unless the transport's reader applies it natively (its ``enforces`` set names it).
TIME_FILTER = "time_filter"
LIFESPAN = "lifespan"
SOURCE_ORDER = "source_order"
DEADLINE = "deadline"

#: Where an option can have an effect besides micros_rt's own endpoints: the microcontroller link's entries
#: (``to_microcontroller``, ``from_microcontroller``, ``services_on_microcontroller``).
MCU_TO, MCU_FROM, MCU_SERVICE = "mcu:to_microcontroller", "mcu:from_microcontroller", "mcu:services"


def _fmt_secs(value: float) -> str:
    return f"{value * 1e3:g} ms" if value < 1.0 else f"{value:g} s"


@dataclass(frozen=True)
class QoSOption:
    """Everything micros_rt knows about one QoS option, in one place.

    ``kind`` ("priority", "duration", "bool" or "callback") gives validation and the XML-RPC/YAML form;
    ``check`` adds the option's own rule (in words). ``dds_policy`` names the DDS policy it maps to (None: not
    mapped, see :mod:`micros_rt.qos.mapping`); ``enforcer`` the check micros_rt applies itself on every
    transport (a transport reader that applies it natively lists it in ``enforces``) and ``counter`` the
    statistics field that counts what that check drops; ``admission`` makes that check for one subscriber from
    the option's value there (an :class:`~micros_rt.qos.enforcement.Admission`, which the subscription runs
    where it is active and counts in ``counter``; None: no per-message check, as the deadline's monitor). ``words``/``short`` describe a value for
    ``micros-rt topic info`` and for ``micros-rt graph`` (None: nothing worth saying, the default).
    ``applies`` lists the bridge entries (``MCU_*``) the option has an effect on. Everything else (the option
    classes' keys, validation, ``to_dict``/``from_dict``, the CLI's words, the key lists of bridges) derives
    from :data:`OPTIONS`; adding an option is a field, an entry here and its enforcer (an Admission).
    """

    name: str
    side: str                                   # "advertise" or "subscribe"
    kind: str
    summary: str
    dds_policy: Optional[str] = None
    enforcer: Optional[str] = None
    counter: Optional[str] = None
    admission: Optional[Callable[[Any], Admission]] = None
    check: Optional[Callable[[Any], None]] = None
    words: Callable[[Any], Optional[str]] = lambda _v: None
    short: Callable[[Any], Optional[str]] = lambda _v: None
    applies: frozenset[str] = frozenset()

    @property
    def wire(self) -> bool:
        """Travels in ``to_dict``/``from_dict`` (XML-RPC, YAML): every kind but a callable."""
        return self.kind != "callback"

    def parse(self, value: Any) -> Any:
        """``value`` validated and normalised (a level, float seconds, a bool), or a QoS error in words."""
        if self.kind == "priority":
            value = TransportPriority.parse(value)
        elif self.kind == "duration":
            value = to_seconds(value, self.name)
        elif self.kind == "bool":
            _check_bool(value, self.name)
        if self.check is not None:
            self.check(value)
        return value

    def encode(self, value: Any) -> Any:
        """The XML-RPC- and YAML-safe form: a level by name, forever as ``"inf"``."""
        if self.kind == "priority":
            return value.name
        if self.kind == "duration":
            return _encode_duration(value)
        return value

    def decode(self, value: Any) -> Any:
        """Inverse of :meth:`encode` (also takes what :meth:`parse` takes)."""
        return _decode_duration(value, self.name) if self.kind == "duration" else value


def _no_zero_lifespan(value: float) -> None:
    if value == 0.0:
        # A zero lifespan expires every message before it can be delivered.
        raise QoSValueError(
            "msg_valid_period=0.0 is invalid: every message would expire before delivery; "
            "expected a duration > 0 in seconds, or math.inf (the default) for no expiry"
        )


def _no_zero_deadline(value: float) -> None:
    if value == 0.0:
        raise QoSValueError(
            "deadline=0.0 is invalid: every message would miss it; expected a duration > 0 in "
            "seconds, or math.inf (the default) for no deadline"
        )


def _finite_filter(value: float) -> None:
    if math.isinf(value):
        raise QoSValueError(
            "time_filter_duration=inf is invalid: only the first message would ever be delivered; "
            "expected a finite duration >= 0 in seconds (0 = no filter)"
        )


def _no_data_centric(value: bool) -> None:
    if value:
        _refuse_data_centric_update()


def _callable_or_none(value: Any) -> None:
    if value is not None and not callable(value):
        raise QoSTypeError(
            f"deadline_cb={value!r} is invalid: expected a callable taking one argument, or None"
        )


_ALL_MCU = frozenset({MCU_TO, MCU_FROM})

#: The catalogue: every option of both sides, in the order the CLI describes them.
OPTIONS: tuple[QoSOption, ...] = (
    QoSOption("using_best_effort_protocol", "advertise", "bool",
              "True: no retransmission (subscribers must accept best effort too)", dds_policy="Reliability",
              words=lambda v: "best effort" if v else "reliable", short=lambda v: "best effort" if v else "reliable",
              applies=_ALL_MCU),
    QoSOption("transport_priority", "advertise", "priority",
              "one of 7 levels: the DDS TransportPriority, DSCP and socket priority of the link's packets",
              dds_policy="TransportPriority", words=lambda v: f"priority {v.name}", short=lambda v: v.name,
              applies=frozenset({MCU_TO, MCU_FROM, MCU_SERVICE})),
    QoSOption("latency_budget", "advertise", "duration",
              "seconds the publisher may take to deliver; samples of a topic are batched within it",
              dds_policy="LatencyBudget",
              words=lambda v: f"latency budget {_fmt_secs(v)}" if v > 0 else None,
              short=lambda v: f"budget {v:g} s" if v > 0 else None, applies=frozenset({MCU_FROM})),
    QoSOption("msg_valid_period", "advertise", "duration",
              "lifespan: a message older than this is dropped, not delivered", dds_policy="Lifespan",
              enforcer=LIFESPAN, counter="dropped_expired", admission=Lifespan, check=_no_zero_lifespan,
              words=lambda v: None if math.isinf(v) else f"valid for {_fmt_secs(v)}",
              short=lambda v: None if math.isinf(v) else f"valid {v:g} s", applies=_ALL_MCU),
    QoSOption("data_centric_update", "advertise", "bool",
              "refused: ROS 1 messages have no keys", check=_no_data_centric),
    QoSOption("using_best_effort_protocol", "subscribe", "bool",
              "True: accepts reliable and best-effort publishers", dds_policy="Reliability",
              words=lambda v: "best effort accepted" if v else "reliable",
              short=lambda v: "best effort ok" if v else "reliable", applies=_ALL_MCU),
    QoSOption("deadline", "subscribe", "duration",
              "the longest silence accepted; a miss calls deadline_cb and is counted", enforcer=DEADLINE,
              counter="deadline_missed", check=_no_zero_deadline,
              words=lambda v: None if math.isinf(v) else f"deadline {_fmt_secs(v)}",
              short=lambda v: None if math.isinf(v) else f"deadline {v:g} s", applies=frozenset({MCU_FROM})),
    QoSOption("deadline_cb", "subscribe", "callback", "called with DeadlineMissed when the deadline is missed",
              check=_callable_or_none),
    QoSOption("time_filter_duration", "subscribe", "duration",
              "deliver at most one message per this many seconds (0: no filter)", dds_policy="TimeBasedFilter",
              enforcer=TIME_FILTER, counter="dropped_filtered", admission=TimeFilter, check=_finite_filter,
              words=lambda v: f"time filter {_fmt_secs(v)}" if v > 0 else None,
              short=lambda v: f"filter {v:g} s" if v > 0 else None, applies=_ALL_MCU),
    QoSOption("ordered_by_sending_timestamp", "subscribe", "bool",
              "True: by the publisher's timestamp, a message older than the last delivered is dropped",
              dds_policy="DestinationOrder", enforcer=SOURCE_ORDER, counter="dropped_out_of_order", admission=SourceOrder,
              words=lambda v: "by source time" if v else "by arrival"),
    QoSOption("data_centric_update", "subscribe", "bool",
              "refused: ROS 1 messages have no keys", check=_no_data_centric),
)


def options_of(side: str) -> tuple[QoSOption, ...]:
    """The catalogue's options of one side ("advertise" or "subscribe"), in the CLI's order."""
    return tuple(o for o in OPTIONS if o.side == side)


def wire_keys(side: str) -> tuple[str, ...]:
    """The option names of one side that travel as data (XML-RPC, YAML profiles, bridge configurations)."""
    return tuple(o.name for o in options_of(side) if o.wire)


def enforcers() -> frozenset[str]:
    """The names of every check micros_rt applies itself (what a transport reader may say it ``enforces``)."""
    return frozenset(o.enforcer for o in OPTIONS if o.enforcer is not None)


def drop_counters(*, side: Optional[str] = None, applies: Optional[str] = None) -> tuple[str, ...]:
    """The :class:`~micros_rt.core.stats.SubscriberStatistics` fields that count what the enforcers drop (or
    miss: ``deadline_missed``), in the catalogue's order, once each: of every option, or only of one ``side``'s
    ("advertise", "subscribe") and of those with an effect on a bridge entry (``applies``, an ``MCU_*``)."""
    return tuple(dict.fromkeys(o.counter for o in OPTIONS if o.counter is not None
                               and (side is None or o.side == side) and (applies is None or applies in o.applies)))


def describe(encoded: Mapping[str, Any], side: str, *, short: bool = False) -> list[str]:
    """Words for a ``to_dict`` form (a peer's, missing keys at their defaults), in the catalogue's order."""
    defaults = {f.name: f.default for f in dataclasses.fields(OPTION_CLASSES[side])}
    out = []
    for option in options_of(side):
        if option.wire:
            value = option.decode(encoded[option.name]) if option.name in encoded else defaults[option.name]
            said = (option.short if short else option.words)(option.parse(value))
            if said is not None:
                out.append(said)
    return out


def _normalise(instance: Any, side: str) -> None:
    # Frozen dataclass: normalise through object.__setattr__ exactly once, at construction.
    for option in options_of(side):
        object.__setattr__(instance, option.name, option.parse(getattr(instance, option.name)))


def _encoded(instance: Any, side: str) -> dict[str, Any]:
    return {o.name: o.encode(getattr(instance, o.name)) for o in options_of(side) if o.wire}


def _decoded(cls: Any, side: str, d: Mapping[str, Any], source: str) -> Any:
    _check_keys(cls.__name__, cls._KEYS, d, source)
    by_name = {o.name: o for o in options_of(side)}
    return cls(**{key: by_name[key].decode(value) for key, value in d.items()})


@dataclass(frozen=True)
class AdvertiseQoSOptions:
    """What a publisher offers (micROS ``ros::AdvertiseQoSOptions``; members in the manual's order).

    - ``transport_priority``: one of 7 :class:`TransportPriority` levels (name or int accepted).
    - ``latency_budget``: seconds the publisher may take to deliver; 0 = as soon as possible.
    - ``using_best_effort_protocol``: ``True`` = no retransmission. Subscribers must then also be
      best effort, or the pair is incompatible (see :mod:`micros_rt.qos.compatibility`).
    - ``data_centric_update``: refused with :class:`UnsupportedQoSError` (ROS 1 messages have no keys).
    - ``msg_valid_period``: lifespan of a message in seconds; ``math.inf`` = never expires.

    >>> AdvertiseQoSOptions(transport_priority="HIGH", msg_valid_period=0.1).transport_priority
    <TransportPriority.HIGH: 4>
    """

    transport_priority: TransportPriority = TransportPriority.NORMAL
    latency_budget: float = DURATION_MIN
    using_best_effort_protocol: bool = False
    data_centric_update: bool = False
    msg_valid_period: float = DURATION_MAX

    #: the option names that travel as data, in field order (from :data:`OPTIONS`)
    _KEYS: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        _normalise(self, "advertise")

    def to_dict(self) -> dict[str, Any]:
        """XML-RPC- and YAML-safe form: priority by name, durations as float seconds or ``"inf"``."""
        return _encoded(self, "advertise")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "a dict") -> AdvertiseQoSOptions:
        """Parse the output of :meth:`to_dict` (missing keys keep their defaults).

        ``source`` names where ``d`` came from (a peer, a file) in error messages. Unknown keys raise
        :class:`QoSValueError` listing the known ones.
        """
        decoded: AdvertiseQoSOptions = _decoded(cls, "advertise", d, source)
        return decoded


@dataclass(frozen=True)
class SubscribeQoSOptions:
    """What a subscriber requests (micROS ``ros::SubscribeQoSOptions``; members in the manual's order).

    - ``deadline``: the longest gap (seconds) between messages this subscriber accepts; ``math.inf``
      = no deadline. micros_rt enforces it itself (on DDS and TCPROS links alike).
    - ``deadline_cb``: called when the deadline is missed; needs a finite ``deadline``. Not part of
      equality or hashing (two option values differing only in their callback are the same QoS).
    - ``ordered_by_sending_timestamp``: ``True`` = order by the publisher's timestamp (older samples
      than the last one received are dropped); ``False`` = order of arrival (plain ROS 1 behaviour).
    - ``time_filter_duration``: deliver at most one message per this many seconds; 0 = no filter.
    - ``using_best_effort_protocol``: ``True`` accepts both reliable and best-effort publishers.
    - ``data_centric_update``: refused with :class:`UnsupportedQoSError` (ROS 1 messages have no keys).

    >>> SubscribeQoSOptions(deadline=0.5, deadline_cb=print, time_filter_duration=1.0).time_filter_duration
    1.0
    """

    deadline: float = DURATION_MAX
    deadline_cb: Optional[DeadlineMissedCallback] = field(default=None, compare=False)
    ordered_by_sending_timestamp: bool = True
    time_filter_duration: float = DURATION_MIN
    using_best_effort_protocol: bool = False
    data_centric_update: bool = False

    #: the option names that travel as data, in field order (deadline_cb cannot cross XML-RPC or live in YAML)
    _KEYS: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        _normalise(self, "subscribe")
        if self.deadline_cb is not None and math.isinf(self.deadline):
            raise QoSValueError(
                "deadline_cb is set but deadline=inf: the callback would never fire; "
                "give a finite deadline in seconds, e.g. deadline=0.5"
            )

    def to_dict(self) -> dict[str, Any]:
        """XML-RPC- and YAML-safe form: durations as float seconds or ``"inf"``; no callback."""
        return _encoded(self, "subscribe")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "a dict") -> SubscribeQoSOptions:
        """Parse the output of :meth:`to_dict` (missing keys keep their defaults; never a callback).

        ``source`` names where ``d`` came from in error messages. Unknown keys (``deadline_cb``
        included) raise :class:`QoSValueError` listing the known ones.
        """
        decoded: SubscribeQoSOptions = _decoded(cls, "subscribe", d, source)
        return decoded


def _field_keys(cls: Any, side: str) -> tuple[str, ...]:
    wire = wire_keys(side)
    names = tuple(f.name for f in dataclasses.fields(cls))
    if set(names) != {o.name for o in options_of(side)}:
        raise AssertionError(f"{cls.__name__}'s fields {names} and the catalogue's {side} options differ")
    return tuple(n for n in names if n in wire)


AdvertiseQoSOptions._KEYS = _field_keys(AdvertiseQoSOptions, "advertise")
SubscribeQoSOptions._KEYS = _field_keys(SubscribeQoSOptions, "subscribe")
#: the option class of each side (its fields' defaults are the options' defaults)
OPTION_CLASSES: dict[str, Any] = {"advertise": AdvertiseQoSOptions, "subscribe": SubscribeQoSOptions}
