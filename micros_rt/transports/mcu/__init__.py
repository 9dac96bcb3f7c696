"""The microcontroller link (seed 003): MessagePack over UDP for topics, TCP for service calls.

``micros-rt mcu-bridge --config mcu.yaml`` runs it (:mod:`micros_rt.bridges.mcu`, which reads the YAML
configuration into a :class:`McuConfig`); docs/mcu.md describes the configuration, the wire format, QoS on the
link and the counters. The transport's pieces:

- :mod:`~micros_rt.transports.mcu.spec`    what a link is made of: addresses, mtu, wire form, streams, services
- :mod:`~micros_rt.transports.mcu.wire`    datagrams, serial datagrams (SLIP + CRC32) and message codecs (pure)
- :mod:`~micros_rt.transports.mcu.link`    sockets, counters, rate-limited warnings; UdpWriter/UdpReader back ends

Importing this package does not import rospy.
"""

from __future__ import annotations

from typing import Any

from .errors import DatagramTooLargeError, McuConfigError, McuServiceError, WireError

__all__ = ["McuConfig", "McuConfigError", "WireError", "DatagramTooLargeError", "McuServiceError"]


def __getattr__(name: str) -> Any:
    if name == "McuConfig":
        from .spec import McuConfig
        return McuConfig
    raise AttributeError(name)
