"""The ``MICROS_RT_*`` settings (:mod:`micros_rt.settings`): one module reads them, the docs' table is the module's,
and each bad value is an error naming the variable, the value and what it takes."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import List

import pytest

from micros_rt import SettingError, settings
from micros_rt.cli.doctor import check_settings

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "micros_rt"
DOC = ROOT / "docs" / "troubleshooting.md"
_NAME = re.compile(r"MICROS_RT_[A-Z0-9_]+")


def modules_naming_settings(package: Path) -> List[str]:
    """Every module (outside settings.py) whose code names a ``MICROS_RT_*`` variable as a whole string or
    builds one in an f-string: the reads of the environment this package may do only in settings.py."""
    found = set()
    for path in package.rglob("*.py"):
        if path == package / "settings.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            whole = isinstance(node, ast.Constant) and isinstance(node.value, str) and _NAME.fullmatch(node.value)
            built = (isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant)
                     and node.values[0].value == "MICROS_RT_")
            if whole or built:
                found.add(str(path.relative_to(package.parent)))
    return sorted(found)


def test_only_the_settings_module_reads_micros_rt_variables() -> None:
    assert modules_naming_settings(PACKAGE) == []


def test_the_check_finds_a_module_reading_the_environment(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text('import os\nflag = os.environ.get("MICROS_RT_DISABLE_DDS", "")\n')
    (tmp_path / "b.py").write_text('import os\nname = "X"\nv = os.environ.get(f"MICROS_RT_{name}")\n')
    (tmp_path / "c.py").write_text('"""MICROS_RT_DISABLE_DDS in a docstring is words, not a read."""\n')
    assert modules_naming_settings(tmp_path) == [f"{tmp_path.name}/a.py", f"{tmp_path.name}/b.py"]


def _doc_rows() -> List[str]:
    text = DOC.read_text()
    section = text[text.index("\n## Settings\n"):]
    nxt = section.find("\n## ", 1)
    return [line for line in (section if nxt < 0 else section[:nxt]).splitlines() if line.startswith("| `MICROS_RT_")]


def test_the_docs_table_is_the_modules() -> None:
    want = [f"| `{s.name}` | {s.takes} | {s.default} | {s.meaning} |" for s in settings.SETTINGS]
    assert _doc_rows() == want, "docs/troubleshooting.md#settings should read:\n" + "\n".join(want)


def test_every_setting_is_listed_once() -> None:
    names = [s.name for s in settings.SETTINGS]
    assert len(names) == len(set(names)) == 12 and all(_NAME.fullmatch(n) for n in names)


@pytest.mark.parametrize("setting,raw,words", [
    (settings.DISABLE_DDS, "maybe", "is not on or off"),
    (settings.ROS2, "sometimes", "is not on, off or auto"),
    (settings.LEASE_DURATION, "0", "is out of range"),
    (settings.LEASE_DURATION, "soon", "is not a number of seconds"),
    (settings.SEND_BUFFER, "tiny", "is not a size in bytes"),
    (settings.SEND_BUFFER, "1k", "is too small"),
    (settings.MALLOC_ARENA_MAX, "two", "is not a whole number"),
    (settings.MALLOC_ARENA_MAX, "-1", "is negative"),
])
def test_a_bad_value_names_the_variable_the_value_and_what_it_takes(setting: settings.Setting[object], raw: str,
                                                                    words: str) -> None:
    with pytest.raises(SettingError) as caught:
        setting.get({setting.name: raw})
    assert str(caught.value).startswith(f"{setting.name}={raw!r} {words}; expected {setting.takes}"), caught.value
    assert isinstance(caught.value, ValueError)


@pytest.mark.parametrize("setting,raw,value", [
    (settings.DISABLE_SHM, "", False), (settings.DISABLE_SHM, "1", True), (settings.DISABLE_SHM, "0", False),
    (settings.DISABLE_SHM, "false", False), (settings.DISABLE_SHM, " Yes ", True),
    (settings.RECEIVE_PRIORITY, "", True), (settings.RECEIVE_PRIORITY, "off", False),
    (settings.ROS2, "", None), (settings.ROS2, "AUTO", "auto"), (settings.ROS2, "1", "on"),
    (settings.SEND_BUFFER, "16kB", 16384), (settings.SEND_BUFFER, "1MiB", 1 << 20), (settings.SEND_BUFFER, "", None),
    (settings.TYPE_CACHE, "", True), (settings.TYPE_CACHE, "off", False), (settings.TYPE_CACHE, "/tmp/x", Path("/tmp/x")),
    (settings.MALLOC_ARENA_MAX, "", 2), (settings.MALLOC_ARENA_MAX, "0", 0),
    (settings.LEASE_DURATION, "2.5", 2.5), (settings.QOS_PROFILE, "/a/b.yaml", "/a/b.yaml"),
])
def test_values_and_defaults(setting: settings.Setting[object], raw: str, value: object) -> None:
    assert setting.get({setting.name: raw}) == value


def test_check_names_every_bad_variable_and_doctor_says_so() -> None:
    env = {"MICROS_RT_DISABLE_DDS": "maybe", "MICROS_RT_SEND_BUFFER": "tiny", "MICROS_RT_ROS2": "on",
           "MICROS_RT_DISABEL_SHM": "1"}
    with pytest.raises(SettingError, match=r"MICROS_RT_DISABLE_DDS='maybe'.*; MICROS_RT_SEND_BUFFER='tiny'"):
        settings.check(env)
    settings.check({"MICROS_RT_ROS2": "off", "MICROS_RT_PYTHON": "/usr/bin/python3"})   # other names are no error
    check = check_settings(env)
    assert check.failed and "MICROS_RT_DISABLE_DDS='maybe'" in check.detail and "MICROS_RT_DISABEL_SHM" in check.detail
    assert not check_settings({"MICROS_RT_ROS2": "on"}).failed


def test_init_node_refuses_a_bad_setting_before_it_starts_anything() -> None:
    # no master needed: the check comes first (ROS_MASTER_URI names a port nobody listens on)
    env = {**os.environ, "MICROS_RT_LEASE_DURATION": "soon", "ROS_MASTER_URI": "http://127.0.0.1:9/"}
    code = ("import micros_rt, rospy\ntry:\n    micros_rt.init_node('x')\nexcept micros_rt.SettingError as e:\n"
            "    print('refused:', e, rospy.core.is_initialized())\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.startswith("refused: MICROS_RT_LEASE_DURATION='soon' is not a number of seconds"), out
    assert out.stdout.strip().endswith("False"), out.stdout
