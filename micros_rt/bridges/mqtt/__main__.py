"""``micros-rt mqtt-bridge --params params.yaml`` (also ``python -m micros_rt.bridges.mqtt``): mqtt_client's node.

Reads mqtt_client's parameter file, logs each defaulted parameter as mqtt_client does, starts the node
(name ``mqtt_client`` unless ``--name`` or a ``__name:=`` remapping says otherwise) and bridges until
Ctrl-C. Exit code 1 with one line on stderr for a bad params file, an unreadable certificate, a broker
certificate that fails verification against the configured CA, or refused credentials.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
from typing import List

from ...cli import CommandError

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="micros-rt mqtt-bridge",
                                 description="Bridge ROS topics and an MQTT broker, configured with mqtt_client's "
                                             "parameter file (see docs/mqtt.md).")
    ap.add_argument("--params", required=True, help="mqtt_client parameter file (YAML)")
    ap.add_argument("--name", default="mqtt_client", help="ROS node name (default: mqtt_client)")
    ap.add_argument("--print-counters", type=float, default=0.0, metavar="SECONDS",
                    help="print the counters as a JSON line on stdout every SECONDS and at exit (0: never)")
    return ap


def main(argv: List[str]) -> int:
    """Run the bridge until Ctrl-C; see the module docstring."""
    ros_args = [a for a in argv if ":=" in a]
    args = _parser().parse_args([a for a in argv if ":=" not in a])

    from ...transports.mqtt.client import MqttConfigError
    from .params import ParamsError, load_params

    try:
        params, warnings = load_params(args.params)
    except ParamsError as exc:
        raise CommandError(str(exc)) from None

    import micros_rt

    from .bridge import MqttBridge

    micros_rt.init_node(args.name, argv=[sys.argv[0], *ros_args])
    log = logging.getLogger("rosout.micros_rt.mqtt")
    for w in warnings:
        log.warning(w)

    fatal: List[str] = []
    stop = threading.Event()

    def on_fatal(text: str) -> None:
        fatal.append(text)
        stop.set()

    try:
        bridge = MqttBridge(params, on_fatal=on_fatal)
    except (MqttConfigError, micros_rt.TypeMappingError) as exc:
        micros_rt.shutdown("mqtt-bridge: bad configuration")
        raise CommandError(str(exc)) from None

    def print_counters() -> None:
        sys.stdout.write(json.dumps({"event": "counters", **bridge.counters()}) + "\n")
        sys.stdout.flush()

    code = 0
    with bridge:
        bridge.start()
        try:
            while not stop.is_set() and micros_rt.ok():
                stop.wait(args.print_counters or 0.5)
                if args.print_counters:
                    print_counters()
        except KeyboardInterrupt:
            pass
        if fatal:
            code = 1
    if args.print_counters:
        print_counters()
    micros_rt.shutdown("mqtt-bridge stopped")
    if fatal:
        raise CommandError(fatal[0])
    return code


if __name__ == "__main__":
    from ...cli import main as _cli_main

    sys.exit(_cli_main(["mqtt-bridge", *sys.argv[1:]]))   # the command's error handling: one line, no traceback
