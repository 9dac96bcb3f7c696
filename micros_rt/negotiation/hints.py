"""TransportHints: a subscriber's ordered preference of protocols.

>>> TransportHints().tcp().dds().protocols
('TCPROS', 'DDS')
>>> TransportHints().protocols
('SHM', 'DDS', 'TCPROS')
"""

from __future__ import annotations

from typing import Tuple

from .protocol import DDS, DEFAULT_PROTOCOLS, SHM, TCPROS, negotiated_protocols

__all__ = ["TransportHints", "DDS", "SHM", "TCPROS", "DEFAULT_PROTOCOLS"]


class TransportHints:
    """Ordered protocol preference for a subscription, built by chaining.

    ``TransportHints()`` alone means the default order: shared memory (SHM) with a
    micros_rt publisher of the same host and user, DDS, then TCPROS.
    ``.shm()``, ``.dds()`` and ``.tcp()`` append in call order: ``.tcp()`` alone never uses
    SHM or DDS; ``.tcp().dds()`` prefers TCPROS. ``.dds()`` alone connects only to
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
        """Hints offering ``names`` (``"SHM"``, ``"DDS"``, ``"TCPROS"``, or a negotiated transport a program
        registered) in that order (a YAML profile's ``transport_hints``); ValueError names an unknown one."""
        hints = cls()
        known = negotiated_protocols() + (TCPROS,)
        for name in names:
            if name not in known:
                raise ValueError(f"unknown transport {name!r}: expected one of {', '.join(map(repr, known))}")
            hints = hints._with(name)
        return hints

    def shm(self) -> "TransportHints":
        """Add shared memory (iceoryx2) to the preference: used with a micros_rt publisher of the same host
        and Unix user; any other publisher declines it and the next protocol is tried."""
        return self._with(SHM)

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
    def allows_shm(self) -> bool:
        return SHM in self.protocols

    @property
    def allows_tcp(self) -> bool:
        return TCPROS in self.protocols

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TransportHints) and other.protocols == self.protocols

    def __hash__(self) -> int:
        return hash(self.protocols)

    def __repr__(self) -> str:
        if any(p not in (SHM, DDS, TCPROS) for p in self._order):
            return f"TransportHints.from_names({list(self._order)!r})"
        chain = "".join({SHM: ".shm()", DDS: ".dds()"}.get(p, ".tcp()") for p in self._order)
        return f"TransportHints(){chain}"
