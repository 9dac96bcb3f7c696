"""The package's examples hold: every module's doctests run (``>>>`` lines in docstrings), as in the docs."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path
from typing import List

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "micros_rt"


def _modules() -> List[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if ">>>" in path.read_text():
            names.append(name)
    return names


@pytest.mark.parametrize("name", _modules())
def test_the_examples_of_each_module_hold(name: str) -> None:
    failed, tried = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert failed == 0, f"{name}: {failed} of {tried} examples failed (see above)"


def test_the_examples_are_found() -> None:
    tried = sum(doctest.testmod(importlib.import_module(name), report=False).attempted for name in _modules())
    assert len(_modules()) >= 10 and tried >= 40, (len(_modules()), tried)
