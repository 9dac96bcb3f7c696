#!/usr/bin/env python3
"""TransportHints choose the protocol per subscription; print what each connection uses.

Publishes four topics and subscribes to each with a different preference:

    default           DDS first, TCPROS as fallback
    .tcp()            TCPROS only, never DDS
    .dds().tcp()      DDS first (same as the default)
    .tcp().dds()      TCPROS first

A stock ROS publisher only speaks TCPROS: with ``.dds()`` alone nothing is
received from it, and micros_rt logs a warning saying so.

Run against a master:  .venv/bin/python examples/transport_hints.py
"""

from __future__ import annotations

import time

from std_msgs.msg import String

import micros_rt
from micros_rt import TransportHints

CHOICES = {
    "default": TransportHints(),
    "tcp": TransportHints().tcp(),
    "dds_tcp": TransportHints().dds().tcp(),
    "tcp_dds": TransportHints().tcp().dds(),
}


def main() -> None:
    micros_rt.init_node("transport_hints_demo", anonymous=True)
    nh = micros_rt.NodeHandle("hints")
    heard = {name: 0 for name in CHOICES}

    def count(_msg: String, name: str) -> None:
        heard[name] += 1

    pubs = {name: nh.advertise(name, String, 10) for name in CHOICES}
    subs = {name: nh.subscribe(name, String, count, 10, hints, callback_args=name)
            for name, hints in CHOICES.items()}
    deadline = time.monotonic() + 10.0
    while micros_rt.ok() and time.monotonic() < deadline:
        if all(s.get_num_connections() > 0 for s in subs.values()) and all(heard.values()):
            break
        for name, pub in pubs.items():
            pub.publish(String(data=name))
        time.sleep(0.05)
    for name, sub in subs.items():
        transports = sorted(set(sub.connection_transports().values())) or ["no connection"]
        print(f"{sub.resolved_name:<16} hints {CHOICES[name]!r:<34} -> {', '.join(transports)}"
              f"  ({heard[name]} messages)")
    micros_rt.shutdown()


if __name__ == "__main__":
    main()
