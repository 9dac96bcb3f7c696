"""The microcontroller link (seed 003): MessagePack over UDP for topics, TCP for service calls.

``micros-rt mcu-bridge --config mcu.yaml`` runs it; docs/mcu.md describes the configuration, the wire
format, QoS on the link and the counters. The pieces:

- :mod:`~micros_rt.mcu.config`  the YAML configuration (errors name file, line and key)
- :mod:`~micros_rt.mcu.wire`    datagrams, serial datagrams (SLIP + CRC32) and message codecs (pure)
- :mod:`~micros_rt.mcu.link`    sockets, counters, rate-limited warnings; UdpWriter/UdpReader back ends
- :mod:`~micros_rt.mcu.bridge`  the ROS side (micros_rt topics, rospy services)

Importing this package does not import rospy; :class:`McuBridge` does, on first use.
"""

from __future__ import annotations

from typing import Any

from .errors import DatagramTooLargeError, McuConfigError, McuServiceError, WireError

__all__ = ["McuBridge", "McuConfig", "load_config", "parse_config", "McuConfigError", "WireError",
           "DatagramTooLargeError", "McuServiceError"]


def __getattr__(name: str) -> Any:
    if name == "McuBridge":
        from .bridge import McuBridge
        return McuBridge
    if name in ("McuConfig", "load_config", "parse_config"):
        from . import config
        return getattr(config, name)
    raise AttributeError(name)
