"""Links of limited bandwidth, as a YAML profile names them: which peers they reach and how fast they are.

A robot's radio is slower than its computer: a 30 Hz camera asks for 221 Mbit/s, a Wi-Fi link gives 40.
When a sender puts more on a link than it drains, the link's queue fills (50 ms of data in a router or an
access point, a second in some), and every topic waits behind that queue, the 1 kHz control topic too.
A profile's ``links`` section tells micros_rt the link's rate, so that its topics below
``TransportPriority.HIGH`` leave no faster than the link drains, with room kept for the HIGH ones::

    links:
      radio:                      # a name, for messages and `micros-rt topic info`
        peers: [10.0.0.0/24]      # the hosts reached over it (addresses or networks)...
        # interface: wlan0        # ...or the local interface it leaves by
        bandwidth: 40Mbit         # bits per second: 40000000, 40Mbit, 40 Mbit/s, 40mbps, 500kbit, 1Gbit
        reserve: 0.1              # the share kept free for HIGH topics (default 0.1)

What paces (:mod:`micros_rt.transports.pacing`): each TCPROS connection of a topic below HIGH to a peer on
the link gets the kernel's TCP pacing (``SO_MAX_PACING_RATE``), the connections on one link sharing
``bandwidth * (1 - reserve)`` max-min fair by what each sent. Cyclone's UDP has no such control; the DDS
writers below HIGH (a participant of their own, see :meth:`micros_rt.transports.dds.backend.DDSBackend.participant_for`)
get a small UDP send buffer instead (:func:`send_buffer_for`), so they keep little queued in the link. A large
LOW topic is still best carried across such a link over TCPROS (``transport_hints: [TCPROS]``), whose
congestion control and pacing leave the link's queue empty.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

from micros_rt.exceptions import ProfileError

__all__ = ["DEFAULT_RESERVE", "LinkSpec", "LinkSpecError", "parse_bandwidth", "parse_link", "send_buffer_for",
           "send_buffer_below_high"]

#: the share of a link kept free for HIGH topics when a profile does not say
DEFAULT_RESERVE = 0.1

#: the queue a sender of topics below HIGH may keep in the link, in seconds of the link's rate (the kernel
#: doubles what is asked: 2 x 3.3 ms at 40 Mbit/s is 16.5 kB asked, 33 kB held)
_QUEUE_SECONDS = 0.0033
#: below this a camera starved (measured on 40 Mbit/s tbf: 16 kB asked, 33 frames in 6 s; 8 kB, 21; 4 kB, 2)
_MIN_SEND_BUFFER = 16 * 1024


def send_buffer_for(bandwidth: float) -> int:
    """The UDP send buffer (bytes) for DDS writers below HIGH on a link of ``bandwidth`` bit/s: a datagram in
    the link's queue still counts against its socket, so they never have more than about twice this queued
    there, and HIGH topics (sockets of their own) wait behind no more than that.

    >>> send_buffer_for(40e6), send_buffer_for(1e9), send_buffer_for(5e6)
    (16500, 412500, 16384)
    """
    return max(_MIN_SEND_BUFFER, int(bandwidth / 8 * _QUEUE_SECONDS))


def send_buffer_below_high(links: Sequence["LinkSpec"]) -> Optional[int]:
    """The send buffer of a node's DDS writers below HIGH when its profile names ``links``: the slowest link's
    (:func:`send_buffer_for`); None without links (Cyclone's own)."""
    return min(send_buffer_for(link.bandwidth) for link in links) if links else None


_Network = Union[ipaddress.IPv4Network, ipaddress.IPv6Network]

_UNITS = {"": 1, "k": 1e3, "m": 1e6, "g": 1e9}
_BANDWIDTH = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?)\s*([kmg]?)(?:bit(?:s)?(?:/s)?|bps)?\s*$", re.IGNORECASE)
_BANDWIDTH_FORMS = "bits per second as a number or with a unit: 40000000, 40Mbit, 40 Mbit/s, 40mbps, 500kbit, 1Gbit"


def parse_bandwidth(value: Any) -> float:
    """Bits per second from a number or a text such as ``40Mbit`` (units as ``tc``'s: k = 1,000).

    >>> parse_bandwidth("40Mbit"), parse_bandwidth("40 Mbit/s"), parse_bandwidth(5e6), parse_bandwidth("1.5gbps")
    (40000000.0, 40000000.0, 5000000.0, 1500000000.0)
    """
    if isinstance(value, bool):
        raise ValueError(f"{value!r} is not a bandwidth; expected {_BANDWIDTH_FORMS}")
    if isinstance(value, (int, float)):
        rate = float(value)
    else:
        match = _BANDWIDTH.match(str(value))
        if not match or (not match.group(2) and str(value).strip().lower().endswith(("b/s", "bytes"))):
            raise ValueError(f"{value!r} is not a bandwidth; expected {_BANDWIDTH_FORMS}")
        rate = float(match.group(1)) * _UNITS[match.group(2).lower()]
    if not rate > 0 or rate == float("inf"):
        raise ValueError(f"{value!r} is not a bandwidth: it must be a positive, finite number of bits per second")
    return rate


@dataclass(frozen=True)
class LinkSpec:
    """One link of a profile's ``links`` section (see the module's text)."""

    name: str
    bandwidth: float                   #: bits per second
    peers: Tuple[_Network, ...] = ()   #: hosts reached over it, or
    interface: Optional[str] = None    #: the local interface it leaves by
    reserve: float = DEFAULT_RESERVE   #: the share kept free for HIGH topics

    @property
    def paced_rate(self) -> float:
        """Bits per second that all topics below HIGH on this link may use together."""
        return self.bandwidth * (1.0 - self.reserve)

    def reaches(self, peer: str, interface: Optional[str]) -> bool:
        """Whether a connection to address ``peer``, leaving by local ``interface``, crosses this link."""
        if self.interface is not None:
            return interface == self.interface
        try:
            address = ipaddress.ip_address(peer.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        return any(address in network for network in self.peers)

    def describe(self) -> str:
        where = f"interface {self.interface}" if self.interface else ", ".join(str(n) for n in self.peers)
        return f"link {self.name} ({where}, {self.bandwidth / 1e6:g} Mbit/s, {self.reserve:.0%} kept for HIGH)"


_KEYS = ("peers", "interface", "bandwidth", "reserve")


class LinkSpecError(ValueError):
    """A link entry that cannot be used: ``key`` is the key at fault ("" for the entry as a whole)."""

    def __init__(self, key: str, text: str) -> None:
        super().__init__(f"{key}: {text}" if key else text)
        self.key = key
        self.text = text


def parse_link(name: str, body: Any) -> LinkSpec:
    """A :class:`LinkSpec` from one entry of the ``links`` section (``body`` as YAML gives it).

    Raises :class:`LinkSpecError` naming the key at fault (the profile reader adds file and line).

    >>> parse_link("radio", {"peers": ["10.0.0.0/24", "10.1.0.7"], "bandwidth": "40Mbit"}).paced_rate
    36000000.0
    """
    if not isinstance(body, Mapping):
        raise LinkSpecError("", "expected a mapping with 'bandwidth' and 'peers' or 'interface'")
    unknown = [str(k) for k in body if k not in _KEYS]
    if unknown:
        raise LinkSpecError(unknown[0], f"unknown key; known keys: {', '.join(_KEYS)}")
    if "bandwidth" not in body:
        raise LinkSpecError("bandwidth", f"missing; give the link's rate in {_BANDWIDTH_FORMS}")
    try:
        bandwidth = parse_bandwidth(body["bandwidth"])
    except ValueError as exc:
        raise LinkSpecError("bandwidth", str(exc)) from None
    peers_given, interface = body.get("peers"), body.get("interface")
    if (peers_given is None) == (interface is None):
        raise LinkSpecError("", "give either peers (the hosts reached over the link: addresses or networks such as "
                         "10.0.0.0/24) or interface (the local interface it leaves by, e.g. wlan0), not both")
    peers: Tuple[_Network, ...] = ()
    if peers_given is not None:
        items: Sequence[Any] = [peers_given] if isinstance(peers_given, str) else peers_given
        if not isinstance(items, (list, tuple)) or not items:
            raise LinkSpecError("peers", "expected a list of addresses or networks, e.g. [10.0.0.0/24, 10.1.0.7]")
        try:
            peers = tuple(ipaddress.ip_network(str(item), strict=False) for item in items)
        except ValueError as exc:
            raise LinkSpecError("peers", f"{exc} (give addresses or networks such as 10.0.0.0/24)") from None
    elif not isinstance(interface, str) or not interface:
        raise LinkSpecError("interface", f"expected an interface name such as wlan0, got {interface!r}")
    reserve = body.get("reserve", DEFAULT_RESERVE)
    if isinstance(reserve, bool) or not isinstance(reserve, (int, float)) or not 0.0 <= reserve < 1.0:
        raise LinkSpecError("reserve", f"expected the share kept free for HIGH topics, from 0 to below 1 "
                         f"(e.g. 0.1), got {reserve!r}")
    return LinkSpec(name, bandwidth, peers, interface, float(reserve))
