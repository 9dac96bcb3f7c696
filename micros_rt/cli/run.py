"""``micros-rt run``: run an unmodified rospy script with micros_rt underneath.

The script runs in this process as ``python SCRIPT ARGS...`` would run it (``__name__`` is
``"__main__"``, ``sys.argv`` is ``[SCRIPT, *ARGS]``, ``sys.path[0]`` its directory, its exit code and
traceback are its own), after :func:`micros_rt.drop_in.install` has put micros_rt under
``rospy.init_node``, ``rospy.Publisher`` and ``rospy.Subscriber``.
"""

from __future__ import annotations

import argparse
import builtins
import io
import os
import sys
import traceback
import types
from typing import List, Optional, Tuple

from .. import drop_in as _drop_in
from .. import settings
from ..exceptions import MicrosRtError
from ..negotiation.hints import TransportHints
from ..qos import QoSProfile
from . import CommandError

__all__ = ["main"]

_DESCRIPTION = """\
Run an unmodified rospy script as a micros_rt node: its rospy.Publisher/Subscriber topics
use DDS with other micros_rt nodes and TCPROS with stock ROS nodes, negotiated per link.
Everything after SCRIPT is the script's own (its arguments, remappings such as topic:=other,
__name:=, __ns:=, and -h).

In a launch file: <node pkg="my_pkg" type="talker.py" name="talker" launch-prefix="micros-rt run"/>
(micros-rt on roslaunch's PATH, or its absolute path, e.g. /path/to/.venv/bin/micros-rt run)."""

_EPILOG = """\
examples:
  micros-rt run talker.py
  micros-rt run --profile qos.yaml listener.py chatter:=/robot/chatter __name:=listener2
  micros-rt run --hints tcp,dds listener.py
  micros-rt run --hints dds,tcp listener.py    (never shared memory)"""

_VALUE_OPTIONS = ("--profile", "--hints")
_HINTS = {"shm": "shm", "dds": "dds", "tcp": "tcp", "tcpros": "tcp"}


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="micros-rt run", usage="micros-rt run [--profile QOS.yaml] [--hints shm,dds,tcp] SCRIPT [ARGS...]",
        description=_DESCRIPTION, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", metavar="QOS.yaml",
                    help="YAML QoS profile for the script's topics (default: $MICROS_RT_QOS_PROFILE)")
    ap.add_argument("--hints", metavar="shm,dds,tcp", default="shm,dds,tcp",
                    help="protocol preference of every subscription, in order: shm,dds,tcp (default: shared "
                         "memory on one host, DDS, then TCPROS), e.g. dds,tcp, tcp (never DDS or shared memory) or "
                         "shm,dds (micros_rt publishers only)")
    return ap


def _split(argv: List[str]) -> Tuple[List[str], Optional[str], List[str]]:
    """micros-rt's options, SCRIPT, the script's arguments: options end at the first non-option."""
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            i += 1
            break
        if arg in _VALUE_OPTIONS:
            i += 2
        elif arg.startswith("-"):
            i += 1
        else:
            break
    if i >= len(argv):
        return argv, None, []
    return argv[:i], argv[i], argv[i + 1:]


def parse_hints(text: str) -> TransportHints:
    """``"dds,tcp"`` -> ``TransportHints().dds().tcp()`` (``shm`` too); CommandError for anything else."""
    hints = TransportHints()
    names = [n.strip().lower() for n in text.split(",") if n.strip()]
    if not names:
        raise CommandError("--hints: give shm, dds, tcp or several in order, e.g. --hints shm,dds,tcp", code=2)
    for name in names:
        if name not in _HINTS:
            raise CommandError(f"--hints: unknown protocol '{name}' (use shm, dds, tcp or several in order, e.g. "
                               f"shm,dds,tcp)", code=2)
        hints = {"shm": hints.shm, "dds": hints.dds}.get(_HINTS[name], hints.tcp)()
    return hints


def _check_script(script: str) -> None:
    if not os.path.exists(script):
        raise CommandError(f"can't open file '{script}': no such file", code=2)
    if os.path.isdir(script):
        raise CommandError(f"'{script}' is a directory, not a Python script", code=2)
    try:
        with open(script, "rb") as f:
            head = f.read(256)
    except OSError as exc:
        raise CommandError(f"can't open file '{script}': {exc.strerror}", code=2) from None
    first = head.split(b"\n", 1)[0]
    if head.startswith(b"\x7fELF") or (first.startswith(b"#!") and b"python" not in first):
        raise CommandError(f"'{script}' is not a Python script: micros-rt run runs rospy scripts only "
                           "(run other nodes without the prefix)", code=2)


def _load_profile(path: Optional[str]) -> None:
    """A bad profile is a one-line error before the script starts, not a traceback from its init_node."""
    if not path:
        return
    try:
        QoSProfile.load(path)
    except (MicrosRtError, OSError) as exc:
        raise CommandError(f"profile {path}: {exc}", code=2) from None


def _print_script_exception(exc: BaseException, path: str) -> None:
    """The traceback python would print: from the script's first frame on, through sys.excepthook."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_frame.f_code.co_filename != path:
        tb = tb.tb_next
    if tb is not None:
        exc.__traceback__ = tb  # python's default hook prints the exception's own traceback
    try:
        sys.excepthook(type(exc), exc, exc.__traceback__)
    except Exception:
        traceback.print_exception(type(exc), exc, exc.__traceback__)


def _run_as_main(path: str) -> None:
    """Run the file as python runs its main script: its code in a fresh ``__main__`` module that stays
    ``sys.modules["__main__"]`` (threads, atexit handlers and pickle find it after the code returns).
    Not runpy.run_path: that rewrites ``sys.argv[0]`` and puts the old ``__main__`` back."""
    with io.open_code(path) as f:
        code = compile(f.read(), path, "exec", dont_inherit=True)
    main_module = types.ModuleType("__main__")
    main_module.__dict__.update(__file__=path, __builtins__=builtins, __cached__=None)
    sys.modules["__main__"] = main_module
    exec(code, main_module.__dict__)


def main(argv: List[str]) -> int:
    options, script, script_args = _split(argv)
    args = _parser().parse_args(options)
    if script is None:
        raise CommandError("no SCRIPT given (usage: micros-rt run [--profile QOS.yaml] [--hints shm,dds,tcp] "
                           "SCRIPT [ARGS...])", code=2)
    _check_script(script)
    hints = parse_hints(args.hints)
    profile = args.profile or settings.QOS_PROFILE.get()
    _load_profile(profile)

    # what `python SCRIPT ARGS...` sets up, before rospy reads its remapping arguments from sys.argv
    sys.argv = [script, *script_args]
    script_dir = os.path.dirname(os.path.realpath(script))
    if sys.path:
        sys.path[0] = script_dir
    else:
        sys.path.append(script_dir)

    _drop_in.install(profile=profile, hints=hints)
    path = os.path.abspath(script)  # python >= 3.9 makes the main script's __file__ absolute
    try:
        _run_as_main(path)
    except SystemExit:
        raise  # the script's exit code (and message), as python handles it
    except KeyboardInterrupt as exc:
        _print_script_exception(exc, path)
        return 130
    except BaseException as exc:
        _print_script_exception(exc, path)
        return 1
    return 0
