"""docs/layout.md is the map of the code: every package and module under micros_rt/ is named in it, in its own
package's entry (a test, so that the map cannot lag the tree again)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Dict, List

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "micros_rt"
LAYOUT = ROOT / "docs" / "layout.md"
_ENTRY = re.compile(r"^( {2}| {4})([A-Za-z0-9_]+/|[A-Za-z0-9_]+\.py\b)")


def entries(text: str) -> Dict[str, str]:
    """The tree block of layout.md as package path ("" for micros_rt itself, "qos", "transports/dds") -> the
    words of its entry (continuation lines included). Entries are the lines indented by 2 (micros_rt's own) or
    4 (a subpackage of the last 2-indented package); a module's line at 2 belongs to ""."""
    block = text.split("```")[1]
    found: Dict[str, str] = {}
    current, parent = "", ""
    for line in block.splitlines():
        match = _ENTRY.match(line)
        if match and not line.startswith("  micros_rt/"):
            indent, token = match.groups()
            if token.endswith("/"):
                current = token[:-1] if len(indent) == 2 else f"{parent}/{token[:-1]}"
                if len(indent) == 2:
                    parent = current
            else:
                current = "" if len(indent) == 2 else parent
        if line.startswith(("examples/", "tests/", "benchmarks/")):
            current = "(outside)"
        found[current] = found.get(current, "") + " " + line
    return found


def missing(package: Path, text: str) -> List[str]:
    """Modules and packages under ``package`` that layout.md does not name in their package's entry (or, for a
    package without an entry of its own, the nearest enclosing one's)."""
    known = entries(text)
    out: List[str] = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if path.name in ("__init__.py", "__main__.py") or "__pycache__" in rel.parts:
            continue
        parts = list(rel.parent.parts)
        while "/".join(parts) not in known:
            parts.pop()
        if not re.search(rf"(?<![\w/]){re.escape(path.name)}\b", known["/".join(parts)]):
            out.append(str(rel))
    for path in sorted(p for p in package.rglob("*") if p.is_dir() and (p / "__init__.py").exists()):
        rel = path.relative_to(package)
        if "/".join(rel.parts) in known:
            continue
        parts = list(rel.parent.parts)
        while "/".join(parts) not in known:
            parts.pop()
        if f"{path.name}/" not in known["/".join(parts)]:
            out.append(f"{rel}/")
    return out


def test_layout_names_every_module_and_package() -> None:
    assert missing(PACKAGE, LAYOUT.read_text()) == []


def test_the_check_finds_what_is_missing(tmp_path: Path) -> None:
    for name in ("a.py", "qos/__init__.py", "qos/options.py", "qos/links.py", "bridges/__init__.py",
                 "bridges/relay/__init__.py", "bridges/relay/ros2.py", "bridges/mcu/__init__.py"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("")
    text = ("```\nmicros_rt/\n  a.py        one\n  qos/        options.py, and\n              more\n"
            "  bridges/    relay/ (relay.py)\n```\n")
    assert missing(tmp_path, text) == ["bridges/relay/ros2.py", "qos/links.py", "bridges/mcu/"]
