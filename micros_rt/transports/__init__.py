"""Transports: one interface (:mod:`.base`) that TCPROS, DDS, MQTT and the microcontroller link implement,
and the one place sockets are marked with a transport priority (:mod:`.marking`)."""
