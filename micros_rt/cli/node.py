"""``micros-rt node``: the nodes of the ROS 1 master and of ROS 2 (DDS discovery) in one list (``list``)."""

from __future__ import annotations

from typing import List

from ._args import dispatch
from ._bothgraph import list_main

__all__ = ["main"]


def main(argv: List[str]) -> int:
    """``micros-rt node <command> ...``."""
    return dispatch("micros-rt node", "a command-line tool for the nodes of ROS 1 and ROS 2.", {
        "list": (lambda rest: list_main("micros-rt node list", "nodes", rest),
                 "list ROS 1 nodes (master) and ROS 2 nodes (DDS discovery), each marked ROS 1, ROS 2 or ROS 1+2"),
    }, argv)
