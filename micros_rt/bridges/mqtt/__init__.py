"""mqtt_client's node on micros_rt (``micros-rt mqtt-bridge``, ``python -m micros_rt.bridges.mqtt``): :mod:`.bridge`
the node, :mod:`.services` ROS services across MQTT. The MQTT transport itself is
:mod:`micros_rt.transports.mqtt`."""
