"""``micros-rt relay --config relay.yaml`` (also ``python -m micros_rt.bridges.relay``, or a node in a launch
file): carries the configuration's topics between this ROS graph and others over DDS (see
:mod:`micros_rt.bridges.relay.config` for the file, :mod:`micros_rt.bridges.relay.relay` for how).

The node is named ``relay_<graph>`` unless ``--name`` or a ``__name:=`` remapping says otherwise. A bad
configuration is one line on stderr naming file, line and key, and exit code 1. ``--json`` prints
``{"event": "ready"}`` and then the counters (``{"event": "stats", ...}``) every ``--stats-period`` seconds;
deadline misses and recoveries of imports as ``{"event": "deadline"}`` and ``{"event": "recovered"}``;
``--check`` only validates the file.

Exports of more than one transport priority are carried by one process per priority (:mod:`.processes`: each
priority's packets get their own DSCP); ``--one-process`` keeps them all in this one.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, List, Optional

from ... import settings
from ...cli import CommandError
from ...exceptions import MicrosRtError
from ...qos import QoSProfile
from ..program import emit, load, open_bridge, parser, run_command, serve, split_ros_args, start_node, write_line

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = parser("relay", "Carry named topics between ROS graphs (robots with their own masters) over DDS, with QoS "
                         "per topic.",
                config="--config", config_help="relay configuration (YAML)", name=None, name_help="relay_<graph>")
    ap.add_argument("--json", action="store_true", help="print readiness and counters as JSON lines on stdout")
    ap.add_argument("--stats-period", type=float, default=5.0, help="seconds between counters with --json")
    ap.add_argument("--poll-period", type=float, default=1.0,
                    help="seconds between looks for new topics to export and exporters to import from")
    ap.add_argument("--one-process", action="store_true",
                    help="carry exports of every transport priority in this process (their DDS packets then all "
                         "carry the DSCP of the highest)")
    # a child process of a relay (see processes.py): only the exports of one priority
    ap.add_argument("--exports-of", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--family-of", default=None, help=argparse.SUPPRESS)
    return ap


def main(argv: List[str]) -> int:
    """Run the relay until Ctrl-C; see the module docstring."""
    own, ros_args = split_ros_args(argv)
    args = _parser().parse_args(own)

    from .config import RelayConfigError, load_config, send_buffer_for

    config = load(load_config, args.config, RelayConfigError)
    from micros_rt.qos import TransportPriority

    from .processes import Children, child_argv, export_priorities, family, process_name

    priorities = export_priorities(config)
    split = len(priorities) > 1 and not args.one_process and args.exports_of is None
    if args.check:
        ros2_out = sum(1 for e in config.ros2 if e.direction == "export")
        print(f"{args.config}: OK: graph {config.graph}, {len(config.exports)} export rules, "
              f"{len(config.imports)} imports"
              + (f"; exports in {len(priorities)} processes ({', '.join(p.name for p in priorities)})" if split else "")
              + (f"; ROS 2: {ros2_out} exports, {len(config.ros2) - ros2_out} imports" if config.ros2 else ""))
        return 0

    import micros_rt
    from micros_rt.extend import dds_backend

    from .relay import Relay, Share

    start_node(args.name or f"relay_{config.graph}", ros_args,
               qos_profile=_ros2_profile(config) if args.exports_of is None else None)
    # this process's exports: a child's one priority; the first process's, unless children carry them
    mine = [TransportPriority.parse(args.exports_of)] if args.exports_of is not None else ([] if split else priorities)
    if config.link_bandwidth is not None and mine and max(mine) < TransportPriority.HIGH \
            and settings.SEND_BUFFER.get() is None:
        # only exports below HIGH cross the link from here: keep what this process queues in it short (a send
        # buffer the user set stays)
        backend = dds_backend()
        if backend is not None:
            backend.send_buffer_below_high = send_buffer_for(config.link_bandwidth)
    node = micros_rt.node_info().name
    if args.exports_of is not None:   # a child: one priority's exports, nothing else
        share = Share(exports=frozenset([int(TransportPriority.parse(args.exports_of))]), imports=False,
                      family=family(args.family_of or node, config), parent=args.family_of)
    else:
        share = Share(exports=frozenset() if split else None, family=family(node, config),
                      children=tuple(process_name(node, p) for p in priorities) if split else ())
    children = None
    if split:
        children = Children(
            priorities,
            lambda p: child_argv(args.config, process_name(node.rsplit("/", 1)[-1], p), node, p,
                                 poll_period=args.poll_period, json_events=args.json,
                                 stats_period=args.stats_period, ros_args=ros_args),
            lambda p: process_name(node, p), write_line).start()

    def stats() -> None:
        emit("stats", **(children.merge(relay.snapshot()) if children else relay.snapshot()))

    def stopping() -> None:
        if children is not None:
            children.close()
        if args.json:
            stats()

    relay = open_bridge("relay", lambda: Relay(config, poll_period=args.poll_period,
                                               event_cb=emit if args.json else None, share=share),
                        cleanup=children.close if children is not None else None)
    serve("relay", relay, period=args.stats_period if args.json else 0.5,
          started=(lambda: emit("ready", node=relay.node, graph=config.graph)) if args.json else None,
          tick=stats if args.json else None, stopping=stopping)
    return 0


def _ros2_profile(config: Any) -> Optional[QoSProfile]:
    """The node's QoS profile when ``ros2:`` imports keep their ROS 1 publications off DDS: ROS 2 subscribers read
    the original publisher, not a second copy from the relay. The profile ``MICROS_RT_QOS_PROFILE`` names, if
    any, is kept and extended; None when there is nothing to add (``init_node`` reads that profile itself)."""
    names = sorted({e.ros1_name for e in config.ros2 if e.direction == "import"})
    if not names:
        return None
    given = settings.QOS_PROFILE.get()
    try:
        profile = QoSProfile.load(given) if given else QoSProfile()
    except MicrosRtError as exc:   # its errors name its own file and line
        raise CommandError(f"{exc} (MICROS_RT_QOS_PROFILE)") from None
    return profile.with_advertise_transports(names, ("TCPROS",))


if __name__ == "__main__":
    sys.exit(run_command("relay"))
