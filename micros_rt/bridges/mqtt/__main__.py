"""``micros-rt mqtt-bridge --params params.yaml`` (also ``python -m micros_rt.bridges.mqtt``): mqtt_client's node.

Reads mqtt_client's parameter file, logs each defaulted parameter as mqtt_client does, starts the node
(name ``mqtt_client`` unless ``--name`` or a ``__name:=`` remapping says otherwise) and bridges until
Ctrl-C. Exit code 1 with one line on stderr for a bad params file, an unreadable certificate, a broker
certificate that fails verification against the configured CA, or refused credentials.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from typing import List

import micros_rt

from ...cli import CommandError
from ..program import emit, load, open_bridge, parser, run_command, serve, split_ros_args, start_node

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = parser("mqtt-bridge", "Bridge ROS topics and an MQTT broker, configured with mqtt_client's parameter file "
                               "(see docs/mqtt.md).",
                config="--params", config_help="mqtt_client parameter file (YAML)", name="mqtt_client", check=False)
    ap.add_argument("--print-counters", type=float, default=0.0, metavar="SECONDS",
                    help="print the counters as a JSON line on stdout every SECONDS and at exit (0: never)")
    return ap


def main(argv: List[str]) -> int:
    """Run the bridge until Ctrl-C; see the module docstring."""
    own, ros_args = split_ros_args(argv)
    args = _parser().parse_args(own)

    from ...transports.mqtt.client import MqttConfigError
    from .params import ParamsError, load_params

    params, warnings = load(load_params, args.params, ParamsError)

    from .bridge import MqttBridge

    start_node(args.name, ros_args)
    log = logging.getLogger("rosout.micros_rt.mqtt")
    for w in warnings:
        log.warning(w)

    fatal: List[str] = []
    stop = threading.Event()

    def on_fatal(text: str) -> None:
        fatal.append(text)
        stop.set()

    bridge = open_bridge("mqtt-bridge", lambda: MqttBridge(params, on_fatal=on_fatal),
                         errors=(MqttConfigError, micros_rt.TypeMappingError))

    def print_counters() -> None:
        emit("counters", **bridge.counters())

    serve("mqtt-bridge", bridge, period=args.print_counters or 0.5, started=bridge.start, stop=stop,
          tick=print_counters if args.print_counters else None,
          closed=print_counters if args.print_counters else None)
    if fatal:
        raise CommandError(fatal[0])
    return 0


if __name__ == "__main__":
    sys.exit(run_command("mqtt-bridge"))
