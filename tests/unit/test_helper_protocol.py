"""The ROS 2 helper's frames have one table of op codes (:mod:`micros_rt.services.helper_protocol`): the gateway and
the helper import it and define none of their own, and the helper imports beside rospy without rclpy."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from typing import List

from micros_rt.services import gateway, helper_protocol, ros2_helper

SERVICES = Path(helper_protocol.__file__).resolve().parent


def op_codes_defined(path: Path) -> List[str]:
    """Names of the protocol's op codes that ``path`` assigns itself (not imported from helper_protocol)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for name in ast.walk(target):
                    if isinstance(name, ast.Name) and name.id in helper_protocol.OPS:
                        found.append(name.id)
    return sorted(found)


def test_the_gateway_and_the_helper_define_no_op_code_of_their_own() -> None:
    assert op_codes_defined(SERVICES / "gateway.py") == []
    assert op_codes_defined(SERVICES / "ros2_helper.py") == []


def test_the_check_finds_a_second_table(tmp_path: Path) -> None:
    (tmp_path / "h.py").write_text("HELLO = 24\nSTATUS, RESULT = 20, 21\nOTHER = 3\n")
    assert op_codes_defined(tmp_path / "h.py") == ["HELLO", "RESULT", "STATUS"]


def test_both_sides_have_every_op_code_of_the_table() -> None:
    assert len(helper_protocol.OPS) == 30 and len(set(helper_protocol.OPS.values())) == 30
    for name, value in helper_protocol.OPS.items():
        assert getattr(gateway, name) == value and getattr(ros2_helper, name) == value, name
    # one encoder and one reader of frames, both sides
    for name in ("encode", "read_frame"):
        assert getattr(gateway, name) is getattr(ros2_helper, name) is getattr(helper_protocol, name), name


def test_the_helper_imports_without_rclpy_and_its_protocol_without_micros_rt() -> None:
    # beside rospy (this venv has no rclpy): the module imports, for the doctests and this test
    out = subprocess.run([sys.executable, "-c", "import micros_rt.services.ros2_helper as h; print(h.HELLO)"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "24", out.stderr
    # as the helper's interpreter sees it: helper_protocol.py from its own directory, nothing of micros_rt
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import helper_protocol; "
            "print(helper_protocol.HELLO, 'micros_rt' in sys.modules)")
    out = subprocess.run([sys.executable, "-I", "-c", code, str(SERVICES)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.split() == ["24", "False"], out.stderr
