"""What every bridge's command does around its bridge (``micros-rt mqtt-bridge``, ``mcu-bridge``, ``relay``, and
``python -m micros_rt.bridges.<name>``): its arguments beside ROS remappings, its configuration's errors as one
line and exit code 1, ``--check``, the node's start, a bridge that cannot start, JSON lines on stdout, the loop
until Ctrl-C (SIGINT/SIGTERM: rospy shuts the node down) and the node's shutdown.

A bridge's ``__main__`` keeps only what is its own: its options, its configuration and its bridge.

>>> split_ros_args(["--config", "r.yaml", "__name:=relay_x", "/chatter:=/talk"])
(['--config', 'r.yaml'], ['__name:=relay_x', '/chatter:=/talk'])
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from typing import Any, Callable, ContextManager, List, Optional, Tuple, Type, TypeVar, Union

import micros_rt

from ..cli import CommandError
from ..qos import QoSProfile

__all__ = ["emit", "load", "open_bridge", "parser", "run_command", "serve", "split_ros_args", "start_node", "write_line"]

T = TypeVar("T")

_out_lock = threading.Lock()


def parser(command: str, description: str, *, config: str, config_help: str, name: Optional[str],
           name_help: str = "", check: bool = True) -> argparse.ArgumentParser:
    """The command's parser with what every bridge takes: its file (``config``, e.g. ``--config``, required), the
    node's ``--name`` (default ``name``) and, with ``check``, ``--check`` (validate the file and exit)."""
    ap = argparse.ArgumentParser(prog=f"micros-rt {command}", description=description)
    ap.add_argument(config, required=True, help=config_help)
    ap.add_argument("--name", default=name, help=f"ROS node name (default: {name_help or name})")
    if check:
        ap.add_argument("--check", action="store_true", help="validate the configuration and exit")
    return ap


def split_ros_args(argv: List[str]) -> Tuple[List[str], List[str]]:
    """``argv`` as (the command's own arguments, ROS remappings such as ``__name:=x``)."""
    return [a for a in argv if ":=" not in a], [a for a in argv if ":=" in a]


def load(read: Callable[[str], T], path: str, errors: Union[Type[Exception], Tuple[Type[Exception], ...]]) -> T:
    """``read(path)``; a configuration error (one of ``errors``, whose message names file, line and key) is the
    command's one line on stderr and exit code 1."""
    try:
        return read(path)
    except errors as exc:
        raise CommandError(str(exc)) from None


def start_node(name: str, ros_args: List[str], *, qos_profile: Optional[QoSProfile] = None) -> None:
    """The bridge's node: ``name`` unless a ``__name:=`` remapping in ``ros_args`` says otherwise."""
    micros_rt.init_node(name, argv=[sys.argv[0], *ros_args], qos_profile=qos_profile)


def open_bridge(command: str, make: Callable[[], T], *,
                errors: Tuple[Type[Exception], ...] = (micros_rt.MicrosRtError,),
                cleanup: Optional[Callable[[], None]] = None) -> T:
    """``make()``; when it fails (one of ``errors``), ``cleanup()``, the node shut down and the reason as the
    command's one line on stderr, exit code 1."""
    try:
        return make()
    except errors as exc:
        if cleanup is not None:
            cleanup()
        micros_rt.shutdown(f"{command}: cannot start")
        raise CommandError(str(exc)) from None


def serve(command: str, bridge: ContextManager[Any], *, period: float = 0.5,
          started: Optional[Callable[[], None]] = None, tick: Optional[Callable[[], None]] = None,
          stopping: Optional[Callable[[], None]] = None, closed: Optional[Callable[[], None]] = None,
          stop: Optional[threading.Event] = None) -> None:
    """Run ``bridge`` (a context manager) until Ctrl-C, the node's shutdown or ``stop``: ``started()`` once it is
    entered, ``tick()`` every ``period`` seconds, ``stopping()`` before it closes, ``closed()`` after; then the
    node shuts down."""
    stop = stop or threading.Event()
    with bridge:
        if started is not None:
            started()
        try:
            while not stop.is_set() and micros_rt.ok():
                stop.wait(period)
                if tick is not None:
                    tick()
        except KeyboardInterrupt:
            pass
        if stopping is not None:
            stopping()
    if closed is not None:
        closed()
    micros_rt.shutdown(f"{command} stopped")


def write_line(line: str) -> None:
    """One line on stdout, whole, flushed (lines of several threads never interleave)."""
    with _out_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def emit(event: str, **fields: Any) -> None:
    """An event as a JSON line on stdout: ``{"event": event, **fields}``."""
    write_line(json.dumps({"event": event, **fields}, default=str))


def run_command(command: str, argv: Optional[List[str]] = None) -> int:
    """``python -m micros_rt.bridges.<name>``: the ``micros-rt`` command's ``command``, with its error handling
    (one line on stderr, no traceback)."""
    from ..cli import main as cli_main

    return cli_main([command, *(sys.argv[1:] if argv is None else argv)])
