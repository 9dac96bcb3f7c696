"""README.md and docs/*.md name only things that exist: files, links and their anchors, `micros-rt` commands
and their options. README stays short enough to read in ten minutes.

Pure reading of the repository plus ``micros-rt <command> -h`` in this process (no ROS master, no network);
the whole module runs in about a second.
"""

from __future__ import annotations

import contextlib
import functools
import glob
import io
import re
import unicodedata
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Set, Tuple

import pytest

from micros_rt import cli

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
README_MAX_LINES = 250

#: directories of this repository whose paths the pages name (``scripts/demo.sh``, ``tests/peers/...``)
REPO_DIRS = ("scripts", "benchmarks", "examples", "tests", "micros_rt", "docs", ".ci")
_PATH = re.compile(r"(?<![\w./~$-])(?:\./)?((?:%s)/[\w./*+-]*)" % "|".join(re.escape(d) for d in REPO_DIRS))
#: a path relative to the package, as the pages write them inside micros_rt (``core/publication.py``)
_PACKAGE_PATH = re.compile(r"`((?:qos|negotiation|transports|core|bridges|cli)/[\w./-]+\.py)`")
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_COMMAND = re.compile(r"(?:micros-rt|python -m micros_rt)\s+([a-z][a-z0-9-]*)(?=[\s`'\"|)]|$)(.*)")
_FENCE = re.compile(r"^\s*```")


def page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped (not ``-`` or ``_``), spaces -> ``-``."""
    text = heading.strip().lower()
    text = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return text.replace(" ", "-")


@functools.lru_cache(maxsize=None)
def anchors(page: Path) -> Set[str]:
    """Every heading anchor of a markdown page (repeats get ``-1``, ``-2``, as on GitHub)."""
    seen: Dict[str, int] = {}
    out: Set[str] = set()
    for line, in_code in lines_of(page):
        m = re.match(r"^(#{1,6})\s+(.*?)\s*#*\s*$", line)
        if m and not in_code:
            base = github_anchor(m.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def lines_of(page: Path) -> Iterator[Tuple[str, bool]]:
    """(line, inside a fenced code block) for every line of a page."""
    in_code = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            in_code = not in_code
            yield line, True
            continue
        yield line, in_code


def code_lines(page: Path) -> Iterator[str]:
    """The code a page shows: lines of fenced blocks, indented lines that run a command, and inline code spans."""
    for line, in_code in lines_of(page):
        if in_code or re.match(r"^ {4,}(?:\.venv/|micros-rt|python|\./scripts)", line):
            yield line
        else:
            yield from re.findall(r"`([^`]+)`", line)


def exists(rel: str) -> bool:
    rel = rel.rstrip("/")
    if any(c in rel for c in "*?["):
        return bool(glob.glob(str(ROOT / rel)))
    return (ROOT / rel).exists()


def named_paths(page: Path) -> List[str]:
    text = page.read_text(encoding="utf-8").replace("$PWD/", "")
    found = []
    for m in _PATH.finditer(text):
        if text[m.end():m.end() + 1] in ("<", "{"):  # a name with a placeholder (an MQTT topic), not a file
            continue
        path = re.split(r"::|:\d", m.group(1))[0].rstrip(".,;:")
        if path.rstrip("/") not in REPO_DIRS:
            found.append(path)
    found += ["micros_rt/" + p for p in _PACKAGE_PATH.findall(text)]
    return found


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_file_a_page_names_exists(page: Path) -> None:
    missing = sorted({p for p in named_paths(page) if not exists(p)})
    assert not missing, f"{page_id(page)} names files that do not exist: {missing}"


def broken_links(page: Path) -> List[str]:
    """Relative links (and their #anchors) of a page that point at nothing in this repository."""
    broken = []
    for target in _LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:: not this repository's
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        try:
            dest.relative_to(ROOT)
        except ValueError:
            broken.append(f"{target} (outside the repository)")
            continue
        if not dest.exists():
            broken.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target} (no heading with that anchor)")
    return broken


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_relative_link_and_anchor_resolves(page: Path) -> None:
    assert not broken_links(page), f"{page_id(page)} has broken links: {broken_links(page)}"


def test_a_broken_link_is_caught(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("# Title\n\nSee [b](b.md), [here](#title) and [there](#nowhere).\n")
    page = tmp_path / "a.md"
    # outside ROOT: every relative link is reported as such; the checker itself is what is tested here
    assert broken_links(page) == ["b.md (outside the repository)", "#title (outside the repository)",
                                  "#nowhere (outside the repository)"]
    assert github_anchor("Constrained link (a robot's radio)") == "constrained-link-a-robots-radio"
    assert github_anchor("Robots and stock nodes: `micros-rt relay`") == "robots-and-stock-nodes-micros-rt-relay"
    assert github_anchor("mqtt_client 1.x and 2.x") == "mqtt_client-1x-and-2x"


@functools.lru_cache(maxsize=None)
def help_text(*argv: str) -> str:
    """What ``micros-rt ARGV -h`` prints (argparse's help, or a command's list of second-level commands)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            cli.main([*argv, "-h"])
        except SystemExit:
            pass
    return out.getvalue() + err.getvalue()


def second_level(name: str) -> Optional[Set[str]]:
    """The second-level commands of ``micros-rt NAME`` (``topic info``), or None when it has none."""
    text = help_text(name)
    if "Commands:" not in text:
        return None
    return set(re.findall(r"^\tmicros-rt %s (\S+)\t" % re.escape(name), text, re.M))


def named_commands(page: Path) -> List[Tuple[str, str]]:
    """(``micros-rt`` subcommand, the rest of the line) for every command a page shows as code."""
    found = []
    for code in code_lines(page):
        for m in _COMMAND.finditer(code):
            found.append((m.group(1), m.group(2).split(" #")[0]))
    return found


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_micros_rt_command_and_option_exists(page: Path) -> None:
    problems = []
    for name, rest in named_commands(page):
        if name not in cli.SUBCOMMANDS:
            problems.append(f"micros-rt {name}: no such command (commands: {', '.join(cli.SUBCOMMANDS)})")
            continue
        argv = [name]
        words = rest.split()
        subs = second_level(name)
        if subs is not None and words and re.fullmatch(r"[a-z][a-z-]*", words[0]):
            if words[0] not in subs:
                problems.append(f"micros-rt {name} {words[0]}: no such command (has: {', '.join(sorted(subs))})")
                continue
            argv.append(words.pop(0))
        options = []
        for word in words:
            if word.endswith(".py") or word in ("|", "&&", ";"):  # the script's own arguments, or the next command
                break
            options += re.findall(r"^\[?(--[a-z][a-z0-9-]*)", word)
        text = help_text(*argv)
        problems += [f"micros-rt {' '.join(argv)} {opt}: no such option" for opt in options if opt not in text]
    assert not problems, f"{page_id(page)}: " + "; ".join(sorted(set(problems)))


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_script_a_page_runs_exists(page: Path) -> None:
    """``python X.py`` / ``./scripts/x.sh`` in code: the file is there."""
    missing = []
    for code in code_lines(page):
        for script in re.findall(r"(?:python3?|^|\s|`)(?:\./)?((?:[\w-]+/)+[\w-]+\.(?:py|sh))\b", code):
            top = script.split("/")[0]
            if top in REPO_DIRS and not exists(script):
                missing.append(script)
    assert not missing, f"{page_id(page)} runs scripts that do not exist: {sorted(set(missing))}"


def test_readme_is_short() -> None:
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines; keep it at most {README_MAX_LINES} (move detail to docs/)"


def test_readme_keeps_the_two_commands() -> None:
    """CI runs the test command README names; the demo is the other one."""
    text = README.read_text(encoding="utf-8")
    assert "./scripts/demo.sh" in text and "./scripts/test.sh" in text
    assert (ROOT / "scripts" / "demo.sh").exists() and (ROOT / "scripts" / "test.sh").exists()


def test_every_page_is_linked_from_readme() -> None:
    text = README.read_text(encoding="utf-8")
    unlinked = [page_id(p) for p in PAGES[1:] if f"]({page_id(p)})" not in text]
    assert not unlinked, f"docs pages README does not link: {unlinked}"
