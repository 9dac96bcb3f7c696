"""The subcommands' argument parser: an argparse error is one line (with the usage) and exit code 2,
raised as :class:`CommandError` like every other user mistake, instead of argparse's two-line message."""

from __future__ import annotations

import argparse
from typing import NoReturn

from . import CommandError

__all__ = ["ArgumentParser"]


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors read ``<problem>; usage: <prog> <args>``."""

    def error(self, message: str) -> NoReturn:
        usage = self.format_usage().strip()
        usage = usage[len("usage: "):] if usage.startswith("usage: ") else usage
        raise CommandError(f"{message}; usage: {usage}", code=2)
