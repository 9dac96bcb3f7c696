"""``micros-rt service``: the services of ROS 1 and ROS 2 together (``list``)."""

from __future__ import annotations

from typing import List

from ._args import dispatch
from ._bothcalls import list_main

__all__ = ["main"]


def main(argv: List[str]) -> int:
    """``micros-rt service <command> ...``."""
    return dispatch("micros-rt service", "a command-line tool for the services of ROS 1 and ROS 2 together.", {
        "list": (lambda rest: list_main("micros-rt service list", "service", rest),
                 "list ROS 1 services (master) and ROS 2 services (DDS discovery) with types, servers and sides"),
    }, argv)
