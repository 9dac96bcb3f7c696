"""MQTT as a micros_rt transport. The mqtt_client-compatible bridge node (``micros-rt mqtt-bridge``) that stands
on it is :mod:`micros_rt.bridges.mqtt`; docs/mqtt.md describes both.

- :mod:`.params`: mqtt_client's connection parameters (``broker``, ``client``), defaults and validation.
- :mod:`.codec`: payload formats (mqtt_client's ROS 1 framing and type announcement, primitive text, JSON).
- :mod:`.generations`: which mqtt_client generation (1.x, 2.x) to write on each topic, from the peers' announcements.
- :mod:`.client`: the paho-mqtt connection (TLS, auth, last will, reconnect, disk buffer).
- :mod:`.backend`: MQTT as a back end of any micros_rt topic, chosen in the YAML profile's ``mqtt`` section
  (a :class:`micros_rt.transports.base.ProfileBackend`: :func:`profile_backend` is what
  ``micros_rt.transports.base`` calls for a profile with an ``mqtt`` section, :func:`close_profile_backend`
  what the node calls at shutdown; nothing here is imported otherwise).
"""

from typing import Any

__all__ = ["ParamsError", "close_profile_backend", "profile_backend"]


def profile_backend(profile: Any, *, graph: str, node: str) -> Any:
    """The process's MQTT back end for ``profile`` (connected at the first call)."""
    from .backend import process_backend

    return process_backend(profile, graph=graph, node=node)


def close_profile_backend() -> None:
    """Disconnect the process's MQTT back end, if one was made (at node shutdown; harmless twice)."""
    from .backend import close_process_backend

    close_process_backend()


def __getattr__(name: str) -> Any:  # imported when used
    if name == "ParamsError":
        from .params import ParamsError

        return ParamsError
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
