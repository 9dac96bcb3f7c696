"""mqtt_client's node on micros_rt (``micros-rt mqtt-bridge``, ``python -m micros_rt.bridges.mqtt``): :mod:`.bridge`
the node, :mod:`.params` its parameter file (mqtt_client's layout), :mod:`.services` ROS services across MQTT. The
MQTT transport itself (the connection, codecs, the broker and client parameters) is
:mod:`micros_rt.transports.mqtt`."""
