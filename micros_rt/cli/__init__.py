"""The ``micros-rt`` command: one entry point, one module per subcommand.

Subcommands are imported only when used, so ``micros-rt run`` pays for nothing it does not run.
Each subcommand module has ``main(argv: list[str]) -> int`` with its own ``argparse`` parser (``prog``
``micros-rt <name>``). A user mistake (unknown topic, no master, bad file) is one line on stderr and a
non-zero exit code, never a traceback: subcommands raise :class:`CommandError` for those.
"""

from __future__ import annotations

import importlib
import sys
from typing import List, Optional, Tuple

__all__ = ["CommandError", "SUBCOMMANDS", "main"]


class CommandError(Exception):
    """A user mistake: printed as ``micros-rt <cmd>: <message>``, exit code ``code``."""

    def __init__(self, message: str, *, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


#: name -> (module implementing it, one line of help). Order is the order of ``micros-rt --help``.
SUBCOMMANDS: dict[str, Tuple[str, str]] = {
    "run": ("micros_rt.cli.run", "run an unmodified rospy script with micros_rt underneath"),
    "topic": ("micros_rt.cli.topic", "list ROS 1 and ROS 2 topics (list), show a topic's links (info), measure its "
              "latency (latency)"),
    "node": ("micros_rt.cli.node", "list ROS 1 and ROS 2 nodes together (list)"),
    "service": ("micros_rt.cli.service", "list ROS 1 and ROS 2 services together, with types and sides (list)"),
    "action": ("micros_rt.cli.action", "list ROS 1 (actionlib) and ROS 2 actions together, with types and sides "
               "(list)"),
    "graph": ("micros_rt.cli.graph", "draw the live graph, links coloured by protocol (--png, --dot)"),
    "doctor": ("micros_rt.cli.doctor", "check the master, network, DDS and profile set-up"),
    "profile": ("micros_rt.cli.profile", "check a YAML QoS profile (and what it matches on a live graph)"),
    "mqtt-bridge": ("micros_rt.bridges.mqtt.__main__", "bridge ROS topics and an MQTT broker (mqtt_client's params)"),
    "mcu-bridge": ("micros_rt.bridges.mcu.__main__", "bridge ROS and a microcontroller (MessagePack over UDP/TCP)"),
    "relay": ("micros_rt.bridges.relay.__main__", "carry named topics between ROS graphs (robots) over DDS, with QoS"),
}


def _usage() -> str:
    width = max(len(n) for n in SUBCOMMANDS)
    lines = [
        "micros-rt is a command-line tool for micros_rt: ROS 1 nodes with DDS and real-time QoS.",
        "",
        "Commands:",
    ]
    lines += [f"\tmicros-rt {name:<{width}}\t{text}" for name, (_, text) in SUBCOMMANDS.items()]
    lines += ["", "Type micros-rt <command> -h for more detailed usage, e.g. 'micros-rt topic -h'"]
    return "\n".join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        _print(_usage())
        return 0 if args else 2
    name, rest = args[0], args[1:]
    if name not in SUBCOMMANDS:
        print(f"micros-rt: unknown command '{name}' (commands: {', '.join(SUBCOMMANDS)})", file=sys.stderr)
        return 2
    module = importlib.import_module(SUBCOMMANDS[name][0])
    try:
        return int(module.main(rest) or 0)
    except CommandError as exc:
        print(f"micros-rt {name}: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `micros-rt ... | head`: the reader left, as with any Unix tool
        _quiet_broken_pipe()
        return 0


def _print(text: str) -> None:
    try:
        print(text, flush=True)
    except BrokenPipeError:
        _quiet_broken_pipe()


def _quiet_broken_pipe() -> None:
    # Python would report the failed flush of stdout at exit: point stdout at /dev/null first
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except OSError:
        pass
