"""``micros-rt mcu-bridge --config mcu.yaml`` (also ``python -m micros_rt.bridges.mcu``): the microcontroller bridge.

Reads the configuration (see :mod:`micros_rt.bridges.mcu.config` and docs/mcu.md), starts the node (name
``mcu_bridge`` unless ``--name`` or a ``__name:=`` remapping says otherwise) and bridges until Ctrl-C.
A bad configuration or a port already in use is one line on stderr and exit code 1.
``--json`` prints the counters (``{"event": "stats", ...}``) every ``stats_period`` and each deadline
miss (``{"event": "deadline", ...}``) as JSON lines on stdout; ``--check`` only validates the file.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from typing import Any, List, Optional

from ...cli import CommandError

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="micros-rt mcu-bridge",
                                 description="Bridge ROS topics and services to a microcontroller: MessagePack "
                                             "datagrams over UDP, service calls over TCP (see docs/mcu.md).")
    ap.add_argument("--config", required=True, help="bridge configuration (YAML)")
    ap.add_argument("--name", default="mcu_bridge", help="ROS node name (default: mcu_bridge)")
    ap.add_argument("--json", action="store_true",
                    help="print counters and deadline misses as JSON lines on stdout")
    ap.add_argument("--check", action="store_true", help="validate the configuration and exit")
    return ap


def _emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}, default=str) + "\n")
    sys.stdout.flush()


def main(argv: List[str]) -> int:
    """Run the bridge until Ctrl-C; see the module docstring."""
    ros_args = [a for a in argv if ":=" in a]
    args = _parser().parse_args([a for a in argv if ":=" not in a])

    from .config import load_config
    from ...transports.mcu.errors import McuConfigError

    try:
        config = load_config(args.config)
    except McuConfigError as exc:
        raise CommandError(str(exc)) from None
    if args.check:
        print(f"{args.config}: OK: {len(config.from_microcontroller)} streams from the board, "
              f"{len(config.to_microcontroller)} topics to it, {len(config.services_on_microcontroller)} services "
              f"on it, {len(config.services_for_microcontroller)} for it")
        return 0

    import micros_rt

    from .bridge import McuBridge

    micros_rt.init_node(args.name, argv=[sys.argv[0], *ros_args])
    deadline_cb = None
    stats_cb = None
    if args.json:
        def deadline_cb(info: Any) -> None:
            _emit("deadline", topic=info.topic, deadline=info.deadline, silent_for=round(info.silent_for, 3),
                  total=info.total_count)

        def stats_cb(snapshot: Any) -> None:
            _emit("stats", **snapshot)
    try:
        bridge = McuBridge(config, deadline_cb=deadline_cb, stats_cb=stats_cb)
    except micros_rt.MicrosRtError as exc:
        micros_rt.shutdown("mcu-bridge: cannot start")
        raise CommandError(str(exc)) from None
    stop = threading.Event()
    with bridge:
        if args.json:
            _emit("ready", stats_topic=bridge.stats_topic)
        try:
            while not stop.is_set() and micros_rt.ok():
                stop.wait(0.2)
        except KeyboardInterrupt:
            pass
        if args.json:
            _emit("stats", **bridge.snapshot())
    micros_rt.shutdown("mcu-bridge stopped")
    return 0


def _run(argv: Optional[List[str]] = None) -> int:
    try:
        return main(list(sys.argv[1:] if argv is None else argv))
    except CommandError as exc:
        print(f"micros-rt mcu-bridge: {exc}", file=sys.stderr)
        return exc.code


if __name__ == "__main__":
    sys.exit(_run())
