"""MQTT for micros_rt: an mqtt_client-compatible bridge node (``micros-rt mqtt-bridge``).

- :mod:`.params`: mqtt_client's parameter layout, defaults and validation.
- :mod:`.codec`: payload formats (mqtt_client's ROS 1 framing and type announcement, primitive text, JSON).
- :mod:`.client`: the paho-mqtt connection (TLS, auth, last will, reconnect, disk buffer).
- :mod:`.bridge`: the node. See docs/mqtt.md.
- :mod:`.backend`: MQTT as a back end of any micros_rt topic, chosen in the YAML profile's ``mqtt`` section;
  :func:`open_writer`/:func:`open_reader` are what the per-topic endpoints call.
"""

from typing import Any, Callable

from .params import MqttParams, ParamsError, load_params, parse_params

__all__ = ["MqttParams", "ParamsError", "load_params", "open_reader", "open_writer", "parse_params"]


def open_writer(spec: Any, options: Any) -> Any:
    """The MQTT mirror of a publication when the node's YAML profile has an ``mqtt`` rule for its topic,
    else None. Imports paho only when a profile has an ``mqtt`` section."""
    backend = _backend()
    return None if backend is None else backend.open_writer(spec, options)


def open_reader(spec: Any, options: Any, deliver: Callable[[Any], None]) -> Any:
    """The MQTT feed of a subscription (``deliver(msg)`` per message) when a rule names its topic, else None."""
    backend = _backend()
    return None if backend is None else backend.open_reader(spec, options, deliver)


def _backend() -> Any:
    from .._runtime import _node

    profile = _node.profile
    if profile is None or not getattr(profile, "mqtt", None):
        return None
    from .._rospy_compat import caller_id
    from .backend import process_backend

    return process_backend(profile, graph=_node.graph, node=caller_id())
