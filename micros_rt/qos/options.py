"""QoS option values of micros_rt: what a publisher offers and what a subscriber requests.

These mirror micROS RT's ``AdvertiseQoSOptions`` / ``SubscribeQoSOptions`` structs (same members,
same order, same defaults) as immutable, validated values. Derive variants with
:func:`dataclasses.replace`::

    >>> opts = AdvertiseQoSOptions(transport_priority="high", latency_budget=0.005)
    >>> dataclasses.replace(opts, using_best_effort_protocol=True)

Durations are float seconds inside: ``0.0`` is ``DURATION_MIN`` and ``math.inf`` is ``DURATION_MAX``.
Strings exist only at the edges (:meth:`TransportPriority.parse`, ``to_dict``/``from_dict`` for XML-RPC
and YAML profiles).
"""

from __future__ import annotations

import datetime
import enum
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Optional

from micros_rt.exceptions import QoSTypeError, QoSValueError, UnsupportedQoSError

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


@dataclass(frozen=True)
class AdvertiseQoSOptions:
    """What a publisher offers (micROS ``ros::AdvertiseQoSOptions``; members in the manual's order).

    - ``transport_priority``: one of 7 :class:`TransportPriority` levels (name or int accepted).
    - ``latency_budget``: seconds the publisher may take to deliver; 0 = as soon as possible.
    - ``using_best_effort_protocol``: ``True`` = no retransmission. Subscribers must then also be
      best effort, or the pair is incompatible (see :mod:`micros_rt.qos.compatibility`).
    - ``data_centric_update``: refused with :class:`UnsupportedQoSError` (ROS 1 messages have no keys).
    - ``msg_valid_period``: lifespan of a message in seconds; ``math.inf`` = never expires.

    >>> AdvertiseQoSOptions(transport_priority="HIGH", msg_valid_period=0.1)
    """

    transport_priority: TransportPriority = TransportPriority.NORMAL
    latency_budget: float = DURATION_MIN
    using_best_effort_protocol: bool = False
    data_centric_update: bool = False
    msg_valid_period: float = DURATION_MAX

    _KEYS: ClassVar[tuple[str, ...]] = (
        "transport_priority",
        "latency_budget",
        "using_best_effort_protocol",
        "data_centric_update",
        "msg_valid_period",
    )

    def __post_init__(self) -> None:
        # Frozen dataclass: normalise through object.__setattr__ exactly once, at construction.
        object.__setattr__(self, "transport_priority", TransportPriority.parse(self.transport_priority))
        object.__setattr__(self, "latency_budget", to_seconds(self.latency_budget, "latency_budget"))
        _check_bool(self.using_best_effort_protocol, "using_best_effort_protocol")
        if _check_bool(self.data_centric_update, "data_centric_update"):
            _refuse_data_centric_update()
        object.__setattr__(
            self, "msg_valid_period", to_seconds(self.msg_valid_period, "msg_valid_period")
        )
        if self.msg_valid_period == 0.0:
            # A zero lifespan expires every message before it can be delivered.
            raise QoSValueError(
                "msg_valid_period=0.0 is invalid: every message would expire before delivery; "
                "expected a duration > 0 in seconds, or math.inf (the default) for no expiry"
            )

    def to_dict(self) -> dict[str, Any]:
        """XML-RPC- and YAML-safe form: priority by name, durations as float seconds or ``"inf"``."""
        return {
            "transport_priority": self.transport_priority.name,
            "latency_budget": _encode_duration(self.latency_budget),
            "using_best_effort_protocol": self.using_best_effort_protocol,
            "data_centric_update": self.data_centric_update,
            "msg_valid_period": _encode_duration(self.msg_valid_period),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "a dict") -> AdvertiseQoSOptions:
        """Parse the output of :meth:`to_dict` (missing keys keep their defaults).

        ``source`` names where ``d`` came from (a peer, a file) in error messages. Unknown keys raise
        :class:`QoSValueError` listing the known ones.
        """
        _check_keys(cls.__name__, cls._KEYS, d, source)
        kwargs: dict[str, Any] = dict(d)
        for key in ("latency_budget", "msg_valid_period"):
            if key in kwargs:
                kwargs[key] = _decode_duration(kwargs[key], key)
        return cls(**kwargs)


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

    >>> SubscribeQoSOptions(deadline=0.5, deadline_cb=print, time_filter_duration=1.0)
    """

    deadline: float = DURATION_MAX
    deadline_cb: Optional[DeadlineMissedCallback] = field(default=None, compare=False)
    ordered_by_sending_timestamp: bool = True
    time_filter_duration: float = DURATION_MIN
    using_best_effort_protocol: bool = False
    data_centric_update: bool = False

    # deadline_cb is deliberately absent: a callable cannot cross XML-RPC or live in YAML.
    _KEYS: ClassVar[tuple[str, ...]] = (
        "deadline",
        "ordered_by_sending_timestamp",
        "time_filter_duration",
        "using_best_effort_protocol",
        "data_centric_update",
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "deadline", to_seconds(self.deadline, "deadline"))
        if self.deadline == 0.0:
            raise QoSValueError(
                "deadline=0.0 is invalid: every message would miss it; expected a duration > 0 in "
                "seconds, or math.inf (the default) for no deadline"
            )
        if self.deadline_cb is not None and not callable(self.deadline_cb):
            raise QoSTypeError(
                f"deadline_cb={self.deadline_cb!r} is invalid: expected a callable taking one "
                f"argument, or None"
            )
        if self.deadline_cb is not None and math.isinf(self.deadline):
            raise QoSValueError(
                "deadline_cb is set but deadline=inf: the callback would never fire; "
                "give a finite deadline in seconds, e.g. deadline=0.5"
            )
        _check_bool(self.ordered_by_sending_timestamp, "ordered_by_sending_timestamp")
        object.__setattr__(
            self,
            "time_filter_duration",
            to_seconds(self.time_filter_duration, "time_filter_duration"),
        )
        if math.isinf(self.time_filter_duration):
            raise QoSValueError(
                "time_filter_duration=inf is invalid: only the first message would ever be delivered; "
                "expected a finite duration >= 0 in seconds (0 = no filter)"
            )
        _check_bool(self.using_best_effort_protocol, "using_best_effort_protocol")
        if _check_bool(self.data_centric_update, "data_centric_update"):
            _refuse_data_centric_update()

    def to_dict(self) -> dict[str, Any]:
        """XML-RPC- and YAML-safe form: durations as float seconds or ``"inf"``; no callback."""
        return {
            "deadline": _encode_duration(self.deadline),
            "ordered_by_sending_timestamp": self.ordered_by_sending_timestamp,
            "time_filter_duration": _encode_duration(self.time_filter_duration),
            "using_best_effort_protocol": self.using_best_effort_protocol,
            "data_centric_update": self.data_centric_update,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "a dict") -> SubscribeQoSOptions:
        """Parse the output of :meth:`to_dict` (missing keys keep their defaults; never a callback).

        ``source`` names where ``d`` came from in error messages. Unknown keys (``deadline_cb``
        included) raise :class:`QoSValueError` listing the known ones.
        """
        _check_keys(cls.__name__, cls._KEYS, d, source)
        kwargs: dict[str, Any] = dict(d)
        for key in ("deadline", "time_filter_duration"):
            if key in kwargs:
                kwargs[key] = _decode_duration(kwargs[key], key)
        return cls(**kwargs)
