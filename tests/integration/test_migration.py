"""docs/migration.md's commands, run as the page gives them (issue 43, deliverable 5): a real rosmaster, stock rospy,
``micros-rt run``, ``micros-rt relay``, an rclpy node, ``rostopic`` and the ``micros-rt`` tools, in one bash
session (so ``&`` and ``kill %1`` mean what they mean to a user), each foreground command's output checked
against the page.

The page's ``console`` blocks are the script: a line starting ``$ `` is a command, the lines after it its expected
output. A line ``...`` skips any lines; ``...`` inside a line matches anything; digits match any digits; runs of
spaces match runs of spaces (table columns). The session runs in a directory of its own (the commands' files:
talker.log, relay.yaml, ...) that sees the repository's ``tests`` and ``.venv-ros2``, with the environment the
page's set-up block exports (this run's master and DDS domain), and ``.venv/bin`` first on PATH as after
``. .venv/bin/activate``.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from pathlib import Path
from typing import Dict, List, Tuple

import pytest

import harness

pytestmark = pytest.mark.integration

PAGE = harness.REPO_ROOT / "docs" / "migration.md"
MARK = "@@migration@@"
T = 150.0  # the whole session's bound (about 15 s when the machine is idle)


def page_commands(text: str) -> List[Tuple[str, List[str]]]:
    """(command, expected output lines) of every ``console`` block, in order."""
    steps: List[Tuple[str, List[str]]] = []
    for block in re.findall(r"^```console\n(.*?)^```$", text, re.M | re.S):
        for line in block.splitlines():
            if line.startswith("$ "):
                steps.append((line[2:], []))
            elif steps:
                steps[-1][1].append(line)
    return steps


def page_env_names(text: str) -> List[str]:
    """The variables the set-up block exports."""
    setup = re.search(r"^## 0\..*?^```sh\n(.*?)^```$", text, re.M | re.S)
    assert setup, "docs/migration.md has no set-up block"
    return [m for line in setup.group(1).splitlines() if line.startswith("export ")
            for m in re.findall(r"(\w+)=", line.split("#")[0])]


def _line_pattern(expected: str) -> "re.Pattern[str]":
    parts = []
    for piece in re.split(r"(\.\.\.|\d+| {2,})", expected.rstrip()):
        parts.append(".*" if piece == "..." else r"\d+" if piece.isdigit() else r" {2,}" if piece.startswith("  ")
                     and not piece.strip() else re.escape(piece))
    return re.compile("^" + "".join(parts) + r"\s*$")


def matches(expected: List[str], output: List[str]) -> bool:
    """Whether ``output`` has each run of ``expected`` lines between ``...`` lines, in order: the first run at the
    start, the last at the end (unless ``...`` leads or ends), consecutive lines within a run."""
    runs: List[List[str]] = [[]]
    for line in expected:
        if line.strip() == "...":
            runs.append([])
        else:
            runs[-1].append(line)
    at = 0
    for i, run in enumerate(runs):
        patterns = [_line_pattern(x) for x in run]
        if not patterns:
            continue
        last = len(output) - len(patterns)
        starts = [at] if i == 0 else range(at, last + 1)
        found = next((s for s in starts if s <= last and all(p.match(output[s + k]) for k, p in enumerate(patterns))),
                     None)
        if found is None or (i == len(runs) - 1 and found != last):
            return False
        at = found + len(patterns)
    return True


def test_matches_reads_the_page_as_documented() -> None:
    assert matches(["data: \"hello 7\"", "---"], ["data: \"hello 12\"", "---"])
    assert not matches(["a", "b"], ["a", "x", "b"])
    assert matches(["a", "...", "b"], ["a", "x", "b"])
    assert matches(["T  S", "/x  1/0", "..."], ["T      S", "/x     1/0", "/y  2/0"])
    assert not matches(["/x  1/0"], ["/x  1/0", "extra"])
    assert matches(['{"e": "recv", "data": "hello ...", ...}'], ['{"e": "recv", "data": "hello 3", "t": 1.5}'])


def test_the_rclpy_listeners_listing_allows_its_graph_line_after_a_message() -> None:
    """CI's run of stop 51: rclpy's graph counted the talker (``matched``) after the first message had come."""
    ci = ['{"event": "ready", "node": "/ros2_peer_listen", "topic": "/chatter"}', '{"event": "matched", "n": 0}',
          '{"event": "recv", "seq": 0, "data": "hello 12", "t": 1795865440.3278685, "msg": {"data": "hello 12"}}',
          '{"event": "matched", "n": 1}',
          '{"event": "recv", "seq": 1, "data": "hello 13", "t": 1795865440.427959, "msg": {"data": "hello 13"}}',
          '{"event": "recv", "seq": 2, "data": "hello 14", "t": 1795865440.528007, "msg": {"data": "hello 14"}}',
          '{"event": "done", "received": 3}']
    listing = next(expected for command, expected in page_commands(PAGE.read_text(encoding="utf-8"))
                   if "ros2_peer.py listen" in command)
    assert matches(listing, ci)
    assert matches(listing, [ci[0], ci[1], ci[3], ci[2], ci[4], ci[5], ci[6]])  # the usual order
    assert not matches(listing, ci[:2] + ci[3:])                                # a message missing

def test_the_migration_page_runs_as_written(dds_domain: int, tmp_path: Path) -> None:
    text = PAGE.read_text(encoding="utf-8")
    steps = page_commands(text)
    assert len(steps) >= 8, steps
    master = harness.RosMaster(workdir=tmp_path / "master", domain_id=dds_domain).start()
    work = tmp_path / "session"
    work.mkdir()
    for name in ("tests", ".venv-ros2"):
        (work / name).symlink_to(harness.REPO_ROOT / name)
    env: Dict[str, str] = {k: v for k, v in master.env.items() if k != "CYCLONEDDS_URI"}  # the page sets none
    env.update(ROS_IP="127.0.0.1", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(harness.FASTDDS_PROFILE),
               PATH=f"{harness.REPO_ROOT / '.venv' / 'bin'}:{env.get('PATH', os.defpath)}")
    missing = [name for name in page_env_names(text) if name not in env]
    assert not missing, f"the page exports {missing}, which this test does not set"
    script = ["set -u"]
    for i, (command, _) in enumerate(steps):
        script += [f"echo '{MARK} {i}'", command]
    script += [f"echo '{MARK} end'", "kill $(jobs -p) 2>/dev/null", "wait"]
    session = subprocess.Popen(["/bin/bash", "-c", "\n".join(script)], cwd=work, env=env, stdin=subprocess.DEVNULL,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = session.communicate(timeout=T)
    except subprocess.TimeoutExpired:
        os.killpg(session.pid, signal.SIGKILL)
        out, err = session.communicate()
        raise AssertionError(f"the page's commands did not finish in {T} s; last output:\n{out[-3000:]}\n{err[-2000:]}")
    finally:
        try:
            os.killpg(session.pid, signal.SIGKILL)   # anything the session left (its own process group only)
        except ProcessLookupError:
            pass
        master.cleanup()
    outputs: Dict[int, List[str]] = {}
    current = None
    for line in out.splitlines():
        if line.startswith(MARK):
            tag = line.split()[1]
            current = None if tag == "end" else int(tag)
            outputs[current or 0] = outputs.get(current or 0, []) if current is not None else outputs.get(0, [])
        elif current is not None:
            outputs.setdefault(current, []).append(line)
    assert f"{MARK} end" in out, f"the session stopped early:\n{out[-3000:]}\n{err[-3000:]}"
    logs = "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-1500:]}" for p in sorted(work.glob("*.log")))
    for i, (command, expected) in enumerate(steps):
        got = outputs.get(i, [])
        if expected:
            assert matches(expected, got), (f"$ {command}\nexpected (docs/migration.md):\n" + "\n".join(expected)
                                            + "\ngot:\n" + "\n".join(got) + f"\nstderr:\n{err[-3000:]}\n{logs}")
