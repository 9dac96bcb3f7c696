"""A ROS 1 action type for the action peers (stock rospy/actionlib and micros_rt; never rclpy): test_msgs/Fibonacci,
which no Debian ROS 1 package has, built at run time with genpy from the same fields as ROS 2's
test_msgs/action/Fibonacci (goal ``int32 order``, result and feedback ``int32[] sequence``), as actionlib's
genaction would expand a ``Fibonacci.action`` file: FibonacciAction, FibonacciActionGoal/Result/Feedback and
FibonacciGoal/Result/Feedback.

The peers' protocol: a goal of order N gets N feedback messages, the i-th with ``sequence == [i]``, then the result
``fibonacci(N)`` (the first N Fibonacci numbers modulo 2**31 - 1, so that any N fits int32).
"""

from __future__ import annotations

from typing import Any, Dict, List

import genpy.dynamic
from actionlib_msgs.msg import GoalID, GoalStatus  # type: ignore[import-untyped]
from std_msgs.msg import Header

PKG, NAME = "test_msgs", "Fibonacci"
PARTS = {"Goal": "int32 order\n", "Result": "int32[] sequence\n", "Feedback": "int32[] sequence\n"}
_SEP = "=" * 80 + "\n"
_made: Dict[str, Any] = {}


def _definition() -> str:
    deps = {
        f"{PKG}/{NAME}ActionGoal": f"Header header\nactionlib_msgs/GoalID goal_id\n{NAME}Goal goal\n",
        f"{PKG}/{NAME}ActionResult": f"Header header\nactionlib_msgs/GoalStatus status\n{NAME}Result result\n",
        f"{PKG}/{NAME}ActionFeedback": f"Header header\nactionlib_msgs/GoalStatus status\n{NAME}Feedback feedback\n",
        "std_msgs/Header": Header._full_text,
        "actionlib_msgs/GoalID": GoalID._full_text,
        "actionlib_msgs/GoalStatus": GoalStatus._full_text.split(_SEP)[0],
        **{f"{PKG}/{NAME}{part}": text for part, text in PARTS.items()},
    }
    core = f"{NAME}ActionGoal action_goal\n{NAME}ActionResult action_result\n{NAME}ActionFeedback action_feedback\n"
    return core + "".join(f"{_SEP}MSG: {t}\n{text}" for t, text in deps.items())


def action_classes() -> Dict[str, Any]:
    """``{"test_msgs/FibonacciAction": cls, "test_msgs/FibonacciGoal": cls, ...}`` (built once per process)."""
    if not _made:
        _made.update(genpy.dynamic.generate_dynamic(f"{PKG}/{NAME}Action", _definition()))
    return _made


def fibonacci_action() -> Any:
    return action_classes()[f"{PKG}/{NAME}Action"]


def part(name: str) -> Any:
    """``part("Goal")`` -> test_msgs/FibonacciGoal."""
    return action_classes()[f"{PKG}/{NAME}{name}"]


def fibonacci(n: int) -> List[int]:
    seq, a, b = [], 0, 1
    for _ in range(n):
        seq.append(a)
        a, b = b, (a + b) % (2 ** 31 - 1)
    return seq
