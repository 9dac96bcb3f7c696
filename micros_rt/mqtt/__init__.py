"""MQTT for micros_rt: an mqtt_client-compatible bridge node (``micros-rt mqtt-bridge``).

- :mod:`.params`: mqtt_client's parameter layout, defaults and validation.
- :mod:`.codec`: payload formats (mqtt_client's ROS 1 framing and type announcement, primitive text, JSON).
- :mod:`.client`: the paho-mqtt connection (TLS, auth, last will, reconnect, disk buffer).
- :mod:`.bridge`: the node. See docs/mqtt.md.
"""

from .params import MqttParams, ParamsError, load_params, parse_params

__all__ = ["MqttParams", "ParamsError", "load_params", "parse_params"]
