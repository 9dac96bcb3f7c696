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
import os
import json
import sys
import threading
from typing import Any, Dict, List, Optional

from ...cli import CommandError

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="micros-rt relay",
                                 description="Carry named topics between ROS graphs (robots with their own "
                                             "masters) over DDS, with QoS per topic.")
    ap.add_argument("--config", required=True, help="relay configuration (YAML)")
    ap.add_argument("--name", default=None, help="ROS node name (default: relay_<graph>)")
    ap.add_argument("--json", action="store_true", help="print readiness and counters as JSON lines on stdout")
    ap.add_argument("--stats-period", type=float, default=5.0, help="seconds between counters with --json")
    ap.add_argument("--poll-period", type=float, default=1.0,
                    help="seconds between looks for new topics to export and exporters to import from")
    ap.add_argument("--check", action="store_true", help="validate the configuration and exit")
    ap.add_argument("--one-process", action="store_true",
                    help="carry exports of every transport priority in this process (their DDS packets then all "
                         "carry the DSCP of the highest)")
    # a child process of a relay (see processes.py): only the exports of one priority
    ap.add_argument("--exports-of", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--family-of", default=None, help=argparse.SUPPRESS)
    return ap


_out_lock = threading.Lock()


def _write(line: str) -> None:
    with _out_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def _emit(event: str, **fields: Any) -> None:
    _write(json.dumps({"event": event, **fields}, default=str))


def main(argv: List[str]) -> int:
    """Run the relay until Ctrl-C; see the module docstring."""
    ros_args = [a for a in argv if ":=" in a]
    args = _parser().parse_args([a for a in argv if ":=" not in a])

    from .config import RelayConfigError, load_config, send_buffer_for

    try:
        config = load_config(args.config)
    except RelayConfigError as exc:
        raise CommandError(str(exc)) from None
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

    from .relay import Relay, Share

    # this process's exports: a child's one priority; the first process's, unless children carry them
    mine = [TransportPriority.parse(args.exports_of)] if args.exports_of is not None else ([] if split else priorities)
    if config.link_bandwidth is not None and mine and max(mine) < TransportPriority.HIGH:
        # only exports below HIGH cross the link from here: keep what this process queues in it short
        # (before init_node starts DDS; a value the user set stays)
        os.environ.setdefault("MICROS_RT_SEND_BUFFER", str(send_buffer_for(config.link_bandwidth)))
    profile = _ros2_profile(config) if args.exports_of is None else None
    try:
        micros_rt.init_node(args.name or f"relay_{config.graph}", argv=[sys.argv[0], *ros_args], qos_profile=profile)
    finally:
        if profile is not None:
            os.unlink(profile)
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
            lambda p: process_name(node, p), _write).start()
    try:
        relay = Relay(config, poll_period=args.poll_period, event_cb=_emit if args.json else None, share=share)
    except micros_rt.MicrosRtError as exc:
        if children is not None:
            children.close()
        micros_rt.shutdown("relay: cannot start")
        raise CommandError(str(exc)) from None
    stop = threading.Event()
    with relay:
        if args.json:
            _emit("ready", node=relay.node, graph=config.graph)
        try:
            while not stop.is_set() and micros_rt.ok():
                stop.wait(args.stats_period if args.json else 0.5)
                if args.json:
                    _emit("stats", **(children.merge(relay.snapshot()) if children else relay.snapshot()))
        except KeyboardInterrupt:
            pass
        if children is not None:
            children.close()
        if args.json:
            _emit("stats", **(children.merge(relay.snapshot()) if children else relay.snapshot()))
    micros_rt.shutdown("relay stopped")
    return 0


def _ros2_profile(config: Any) -> Optional[str]:
    """A QoS profile (a temporary file, read by ``init_node``) that keeps the ROS 1 publications of ``ros2:``
    imports off DDS: ROS 2 subscribers read the original publisher, not a second copy from the relay. The
    profile ``MICROS_RT_QOS_PROFILE`` names, if any, is kept and extended."""
    import tempfile

    import yaml

    import micros_rt

    names = sorted({e.ros1_name for e in config.ros2 if e.direction == "import"})
    if not names:
        return None
    data: Dict[str, Any] = {}
    given = os.environ.get("MICROS_RT_QOS_PROFILE") or ""
    if given:
        try:
            micros_rt.QoSProfile.load(given)   # its errors name its own file and line
            with open(given, encoding="utf-8") as f:
                data = yaml.safe_load(f) or {}
        except (OSError, yaml.YAMLError, micros_rt.MicrosRtError) as exc:
            raise CommandError(f"{given} (MICROS_RT_QOS_PROFILE): {exc}") from None
    publishers = data.setdefault("publishers", {}) or {}
    data["publishers"] = publishers
    for name in names:
        entry = publishers.get(name) or {}
        entry["transport_hints"] = ["TCPROS"]
        publishers[name] = entry
    fd, path = tempfile.mkstemp(prefix="micros_rt_relay_profile_", suffix=".yaml")
    with os.fdopen(fd, "w") as f:
        yaml.safe_dump(data, f)
    return path


if __name__ == "__main__":
    from ...cli import main as _cli_main

    sys.exit(_cli_main(["relay", *sys.argv[1:]]))   # the command's error handling: one line, no traceback
