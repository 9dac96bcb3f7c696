"""Programs built on the public API and the transports: ``micros-rt mqtt-bridge`` (:mod:`.mqtt`, mqtt_client's
node) and ``micros-rt mcu-bridge`` (:mod:`.mcu`, the microcontroller link's ROS side). Nothing in them
re-implements delivery, QoS enforcement or statistics."""
