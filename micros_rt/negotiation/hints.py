"""TransportHints: a subscriber's ordered preference of protocols.

>>> TransportHints().tcp().dds().protocols
('TCPROS', 'DDS')
"""

from __future__ import annotations

from typing import Tuple

from .protocol import DDS, DEFAULT_PROTOCOLS, TCPROS

__all__ = ["TransportHints", "DDS", "TCPROS", "DEFAULT_PROTOCOLS"]


class TransportHints:
    """Ordered protocol preference for a subscription, built by chaining.

    ``TransportHints()`` alone means the default order, DDS then TCPROS.
    ``.dds()`` and ``.tcp()`` append in call order: ``.tcp()`` alone never uses
    DDS; ``.tcp().dds()`` prefers TCPROS. ``.dds()`` alone connects only to
    publishers that can speak DDS; a stock ROS publisher is then left
    unconnected and micros_rt logs a warning saying so (as ROS 1 does when a
    subscriber asks only for UDPROS and the publisher cannot).

    Hints are immutable: each call returns a new object.
    """

    __slots__ = ("_order",)

    def __init__(self, _order: Tuple[str, ...] = ()) -> None:
        self._order = _order

    def _with(self, protocol: str) -> "TransportHints":
        if protocol in self._order:
            return self
        return TransportHints(self._order + (protocol,))

    @classmethod
    def from_names(cls, names: "Tuple[str, ...] | list[str]") -> "TransportHints":
        """Hints offering ``names`` (``"DDS"``, ``"TCPROS"``) in that order (a YAML profile's
        ``transport_hints``); ValueError names an unknown one."""
        hints = cls()
        for name in names:
            if name not in (DDS, TCPROS):
                raise ValueError(f"unknown transport {name!r}: expected {DDS!r} or {TCPROS!r}")
            hints = hints._with(name)
        return hints

    def dds(self) -> "TransportHints":
        """Add DDS to the preference (Cyclone DDS, with the subscription's QoS)."""
        return self._with(DDS)

    def tcp(self) -> "TransportHints":
        """Add TCPROS, ROS 1's TCP transport, to the preference."""
        return self._with(TCPROS)

    @property
    def protocols(self) -> Tuple[str, ...]:
        """The protocols in preference order (the default order when none was chained)."""
        return self._order or DEFAULT_PROTOCOLS

    @property
    def allows_dds(self) -> bool:
        return DDS in self.protocols

    @property
    def allows_tcp(self) -> bool:
        return TCPROS in self.protocols

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TransportHints) and other.protocols == self.protocols

    def __hash__(self) -> int:
        return hash(self.protocols)

    def __repr__(self) -> str:
        chain = "".join(".dds()" if p == DDS else ".tcp()" for p in self._order)
        return f"TransportHints(){chain}"
