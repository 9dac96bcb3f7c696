"""Reading a negotiated transport's offer or answer from ``requestTopic``: the error every transport raises and
the field readers it validates with.

A transport's offer (subscriber -> publisher) and answer (publisher -> subscriber) live in its own package
(:mod:`micros_rt.transports.dds.offer`, :mod:`micros_rt.transports.shm.offer`); both sides build and read them
only through their ``to_xmlrpc`` / ``from_xmlrpc``, so the keys one side writes are the keys the other reads.
``from_xmlrpc`` validates everything a remote node sends with the readers here (types, lengths, QoS) and raises
:class:`MalformedNegotiationError` naming the field; nothing from the wire is trusted or kept unvalidated.

>>> read_str({"md5": "992c"}, "md5")
'992c'
>>> read_bool({"latch": "yes"}, "latch")
Traceback (most recent call last):
...
micros_rt.negotiation.messages.MalformedNegotiationError: latch: expected a boolean, got 'yes'
"""

from __future__ import annotations

from typing import Any, Mapping, Type, TypeVar

from ..exceptions import MicrosRtError, QoSTypeError, QoSValueError
from ..qos import AdvertiseQoSOptions, SubscribeQoSOptions
from .protocol import MAX_FIELD_CHARS

__all__ = ["INT32", "MalformedNegotiationError", "read_bool", "read_qos", "read_str", "read_struct", "short"]

#: The range of an XML-RPC integer (``<i4>``).
INT32 = (-(2 ** 31), 2 ** 31 - 1)


class MalformedNegotiationError(MicrosRtError, ValueError):
    """An offer or answer from another node is not what micros_rt sends; ``field`` names the key."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


def short(value: object) -> str:
    """A remote-supplied value for an error message (its repr, cut at 60 characters)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def read_struct(params: object, what: str) -> Mapping[str, Any]:
    """``params`` as the struct of an offer or answer (``what`` names it in the error: "DDS offer")."""
    if not isinstance(params, dict):
        raise MalformedNegotiationError(what, f"expected a struct, got {type(params).__name__}")
    return params


def read_str(d: Mapping[str, Any], key: str, *, required: bool = True) -> str:
    """The string at ``key`` (at most :data:`MAX_FIELD_CHARS`); "" for a missing one that is not ``required``."""
    value = d.get(key)
    if value is None and not required:
        return ""
    if not isinstance(value, str):
        raise MalformedNegotiationError(key, f"expected a string, got {short(value)}")
    if len(value) > MAX_FIELD_CHARS:
        raise MalformedNegotiationError(key, f"{len(value)} characters, at most {MAX_FIELD_CHARS} allowed")
    return value


def read_bool(d: Mapping[str, Any], key: str) -> bool:
    """The boolean at ``key`` (False when missing)."""
    value = d.get(key, False)
    if not isinstance(value, bool):
        raise MalformedNegotiationError(key, f"expected a boolean, got {short(value)}")
    return value


Q = TypeVar("Q", SubscribeQoSOptions, AdvertiseQoSOptions)


def read_qos(cls: Type[Q], d: Mapping[str, Any], source: str) -> Q:
    """The ``qos`` struct of an offer or answer as ``cls`` (MalformedNegotiationError naming the field)."""
    try:
        return cls.from_dict(_qos_dict(d), source=source)
    except (QoSValueError, QoSTypeError) as exc:
        raise MalformedNegotiationError("qos", str(exc)[:300]) from exc


def _qos_dict(d: Mapping[str, Any]) -> Mapping[str, Any]:
    qos = d.get("qos", {})
    if not isinstance(qos, dict) or len(qos) > 16:
        raise MalformedNegotiationError("qos", f"expected a struct of QoS options, got {short(qos)}")
    for key, value in qos.items():
        if (isinstance(key, str) and len(key) > MAX_FIELD_CHARS) or (isinstance(value, str)
                                                                     and len(value) > MAX_FIELD_CHARS):
            raise MalformedNegotiationError("qos", f"option {short(key)}: at most {MAX_FIELD_CHARS} characters")
    return qos
