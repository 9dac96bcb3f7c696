"""The relay between ROS graphs (``micros-rt relay --config relay.yaml``, ``python -m micros_rt.bridges.relay``).

Importing this package does not import rospy; :class:`Relay` does, on first use.
"""

from __future__ import annotations

from typing import Any

from .config import RelayConfig, RelayConfigError, load_config, parse_config

__all__ = ["Relay", "RelayConfig", "RelayConfigError", "load_config", "parse_config"]


def __getattr__(name: str) -> Any:
    if name == "Relay":
        from .relay import Relay
        return Relay
    raise AttributeError(name)
