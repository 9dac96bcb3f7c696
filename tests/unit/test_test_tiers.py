"""The fast tier's smoke tests (conftest.SMOKE) exist: a renamed test must not drop out of it silently."""

from __future__ import annotations

import ast
from pathlib import Path

import conftest

ROOT = Path(__file__).resolve().parents[2]


def test_every_smoke_test_exists() -> None:
    missing = []
    for nodeid in conftest.SMOKE:
        path, name = nodeid.split("[")[0].split("::")
        tree = ast.parse((ROOT / path).read_text())
        if name not in {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}:
            missing.append(nodeid)
    assert missing == []
    assert len(conftest.SMOKE) == len(set(conftest.SMOKE)) >= 8
