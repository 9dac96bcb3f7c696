"""``micros-rt action``: the actions of ROS 1 (actionlib) and ROS 2 together (``list``)."""

from __future__ import annotations

from typing import List

from ._args import dispatch
from ._bothcalls import list_main

__all__ = ["main"]


def main(argv: List[str]) -> int:
    """``micros-rt action <command> ...``."""
    return dispatch("micros-rt action", "a command-line tool for the actions of ROS 1 (actionlib) and ROS 2 together.", {
        "list": (lambda rest: list_main("micros-rt action list", "action", rest),
                 "list ROS 1 actionlib actions (master) and ROS 2 actions (DDS discovery) with types, servers and "
                 "sides"),
    }, argv)
