"""The subcommands' argument parser: an argparse error is one line (with the usage) and exit code 2,
raised as :class:`CommandError` like every other user mistake, instead of argparse's two-line message."""

from __future__ import annotations

import argparse
from typing import Callable, List, Mapping, NoReturn, Tuple

from . import CommandError

__all__ = ["ArgumentParser", "Command", "dispatch"]


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors read ``<problem>; usage: <prog> <args>``."""

    def error(self, message: str) -> NoReturn:
        usage = self.format_usage().strip()
        usage = usage[len("usage: "):] if usage.startswith("usage: ") else usage
        raise CommandError(f"{message}; usage: {usage}", code=2)


#: A second-level command: its ``main(argv)`` and one line of help.
Command = Tuple[Callable[[List[str]], int], str]


def dispatch(prog: str, intro: str, commands: Mapping[str, Command], argv: List[str]) -> int:
    """Second-level commands as ``rostopic`` has them: ``prog`` alone or ``-h`` lists them (exit code 2
    or 0), ``prog NAME ARGS`` runs one, an unknown name is a one-line error."""
    if not argv or argv[0] in ("-h", "--help", "help"):
        lines = [f"{prog} is {intro}", "", "Commands:"]
        lines += [f"\t{prog} {name}\t{text}" for name, (_, text) in commands.items()]
        first = next(iter(commands))
        lines += ["", f"Type {prog} <command> -h for more detailed usage, e.g. '{prog} {first} -h'"]
        print("\n".join(lines))
        return 0 if argv else 2
    if argv[0] not in commands:
        raise CommandError(f"unknown command '{argv[0]}' (commands: {', '.join(commands)})", code=2)
    return commands[argv[0]][0](argv[1:])
