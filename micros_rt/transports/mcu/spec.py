"""What a microcontroller link is made of: the board's and the bridge's addresses, the mtu, the wire form, and
the streams and services it carries (:class:`McuConfig`, what :class:`~micros_rt.transports.mcu.link.McuLink`
takes).

The bridge's YAML file (``micros-rt mcu-bridge --config``) is read into these values by
:mod:`micros_rt.bridges.mcu.config`; a program may as well build them in code:

>>> McuConfig(Address("127.0.0.2"), mtu=512).microcontroller.topic()
('127.0.0.2', 20000)
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field
from typing import Any, Optional, Tuple, Type

import genpy

from micros_rt.qos.options import AdvertiseQoSOptions, SubscribeQoSOptions

from .wire import WireForm

__all__ = ["Address", "TopicEntry", "ServiceEntry", "McuConfig", "DEFAULT_TOPIC_PORT", "DEFAULT_SERVICE_PORT",
           "DEFAULT_MTU", "MAX_MTU", "DEFAULT_SERVICE_TIMEOUT"]

DEFAULT_TOPIC_PORT = 20000
DEFAULT_SERVICE_PORT = 20001
DEFAULT_MTU = 1472          # 1500-byte Ethernet MTU - 20 (IPv4) - 8 (UDP)
MAX_MTU = 65507             # the largest IPv4 UDP payload
DEFAULT_SERVICE_TIMEOUT = 2.0


@dataclass(frozen=True)
class Address:
    """An IP address (a literal, v4 or v6) with the link's two ports."""

    address: str
    topic_port: int = DEFAULT_TOPIC_PORT
    service_port: int = DEFAULT_SERVICE_PORT

    @property
    def family_v6(self) -> bool:
        return ipaddress.ip_address(self.address).version == 6

    def topic(self) -> Tuple[str, int]:
        return (self.address, self.topic_port)

    def service(self) -> Tuple[str, int]:
        return (self.address, self.service_port)


@dataclass(frozen=True)
class TopicEntry:
    """One stream: a ROS topic and the datagram name it travels under."""

    topic: str
    type: str
    name: str
    data_class: Type[genpy.Message] = field(compare=False, repr=False)
    advertise: AdvertiseQoSOptions = AdvertiseQoSOptions()
    subscribe: SubscribeQoSOptions = SubscribeQoSOptions(using_best_effort_protocol=True)
    line: int = 0


@dataclass(frozen=True)
class ServiceEntry:
    """One service: a ROS service name, its type and the name it is called by on the wire."""

    service: str
    type: str
    name: str
    service_class: Any = field(compare=False, repr=False)
    timeout: float = DEFAULT_SERVICE_TIMEOUT
    advertise: AdvertiseQoSOptions = AdvertiseQoSOptions()
    line: int = 0


@dataclass(frozen=True)
class McuConfig:
    """The whole link: the board, this end's address, the mtu, the wire form written (None, the default: the era
    the board's own datagrams and requests show, CVRA's final form until it has sent any), the streams each way and
    the services each way (``stats_period`` and ``source`` are the bridge's: how often it reports, which file
    it came from)."""

    microcontroller: Address
    bind: Address = Address("0.0.0.0")
    mtu: int = DEFAULT_MTU
    stats_period: float = 1.0
    wire_form: Optional[WireForm] = None   # None: the board's era, learned from what it sends
    to_microcontroller: Tuple[TopicEntry, ...] = ()
    from_microcontroller: Tuple[TopicEntry, ...] = ()
    services_on_microcontroller: Tuple[ServiceEntry, ...] = ()
    services_for_microcontroller: Tuple[ServiceEntry, ...] = ()
    source: str = "<string>"
