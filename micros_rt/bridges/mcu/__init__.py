"""The microcontroller link's ROS side (``micros-rt mcu-bridge``, ``python -m micros_rt.bridges.mcu``).

The wire, configuration and sockets are :mod:`micros_rt.transports.mcu`; importing this package does not import
rospy, :class:`McuBridge` does, on first use.
"""

from __future__ import annotations

from typing import Any

from ...transports.mcu import McuConfig, load_config, parse_config

__all__ = ["McuBridge", "McuConfig", "load_config", "parse_config"]


def __getattr__(name: str) -> Any:
    if name == "McuBridge":
        from .bridge import McuBridge
        return McuBridge
    raise AttributeError(name)
