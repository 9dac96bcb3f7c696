"""``micros-rt mcu-bridge --config mcu.yaml`` (also ``python -m micros_rt.bridges.mcu``): the microcontroller bridge.

Reads the configuration (see :mod:`micros_rt.bridges.mcu.config` and docs/mcu.md), starts the node (name
``mcu_bridge`` unless ``--name`` or a ``__name:=`` remapping says otherwise) and bridges until Ctrl-C.
A bad configuration or a port already in use is one line on stderr and exit code 1.
``--json`` prints the counters (``{"event": "stats", ...}``) every ``stats_period`` and each deadline
miss (``{"event": "deadline", ...}``) as JSON lines on stdout; ``--check`` only validates the file.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, List

from ..program import emit, load, open_bridge, parser, run_command, serve, split_ros_args, start_node

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = parser("mcu-bridge", "Bridge ROS topics and services to a microcontroller: MessagePack datagrams over UDP, "
                              "service calls over TCP (see docs/mcu.md).",
                config="--config", config_help="bridge configuration (YAML)", name="mcu_bridge")
    ap.add_argument("--json", action="store_true",
                    help="print counters and deadline misses as JSON lines on stdout")
    return ap


def main(argv: List[str]) -> int:
    """Run the bridge until Ctrl-C; see the module docstring."""
    own, ros_args = split_ros_args(argv)
    args = _parser().parse_args(own)

    from .config import load_config
    from ...transports.mcu.errors import McuConfigError

    config = load(load_config, args.config, McuConfigError)
    if args.check:
        print(f"{args.config}: OK: {len(config.from_microcontroller)} streams from the board, "
              f"{len(config.to_microcontroller)} topics to it, {len(config.services_on_microcontroller)} services "
              f"on it, {len(config.services_for_microcontroller)} for it")
        return 0

    from .bridge import McuBridge

    start_node(args.name, ros_args)
    deadline_cb = None
    stats_cb = None
    if args.json:
        def deadline_cb(info: Any) -> None:
            emit("deadline", topic=info.topic, deadline=info.deadline, silent_for=round(info.silent_for, 3),
                 total=info.total_count)

        def stats_cb(snapshot: Any) -> None:
            emit("stats", **snapshot)
    bridge = open_bridge("mcu-bridge", lambda: McuBridge(config, deadline_cb=deadline_cb, stats_cb=stats_cb))
    serve("mcu-bridge", bridge, period=0.2,
          started=(lambda: emit("ready", stats_topic=bridge.stats_topic)) if args.json else None,
          stopping=(lambda: emit("stats", **bridge.snapshot())) if args.json else None)
    return 0


if __name__ == "__main__":
    sys.exit(run_command("mcu-bridge"))
