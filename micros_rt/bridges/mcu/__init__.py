"""The microcontroller link's ROS side (``micros-rt mcu-bridge``, ``python -m micros_rt.bridges.mcu``).

The configuration file is :mod:`.config`; the wire, the link's description and its sockets are
:mod:`micros_rt.transports.mcu`. Importing this package does not import rospy, :class:`McuBridge` does, on
first use.
"""

from __future__ import annotations

from typing import Any

from ...transports.mcu.spec import McuConfig
from .config import load_config, parse_config

__all__ = ["McuBridge", "McuConfig", "load_config", "parse_config"]


def __getattr__(name: str) -> Any:
    if name == "McuBridge":
        from .bridge import McuBridge
        return McuBridge
    raise AttributeError(name)
