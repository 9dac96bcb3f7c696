"""An unmodified actionlib client script: rospy and actionlib, nothing of micros_rt in it.

    plain_action_client.py NAME [--order N] [--cancel-order M] [--cancel-after K] [--wait S]

``actionlib.SimpleActionClient(NAME, test_msgs/FibonacciAction)`` (the type from ros1_action_types.py beside this
file, as a script would import ``my_pkg.msg``), ``wait_for_server(S)``, then a goal of order N, waited for, and a
goal of order M cancelled with ``cancel_goal()`` after K feedback messages. Prints one JSON line per event:
"available" or "unavailable" {elapsed} (then exit code 1), "active" {label} (the goal was accepted), "cancel_sent"
{label, feedback}, "result" {label, status, status_name, text, feedback, feedback_in_order, sequence_ok, elapsed},
"done". Run under ``micros-rt run`` (tests/integration/test_cli_run.py), where it reaches a ROS 2
action server; under /usr/bin/python3 it reaches ROS 1 servers only.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any, List

import actionlib  # type: ignore[import-untyped]
import rospy

from ros1_action_types import fibonacci, fibonacci_action, part

STATUS_NAMES = ("PENDING", "ACTIVE", "PREEMPTED", "SUCCEEDED", "ABORTED", "REJECTED", "PREEMPTING", "RECALLING",
                "RECALLED", "LOST")


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def run_goal(client: Any, label: str, order: int, cancel_after: int = 0) -> None:
    received: List[int] = []
    enough = threading.Event()

    def feedback(fb: Any) -> None:
        received.append(fb.sequence[0] if fb.sequence else -1)
        if cancel_after and len(received) >= cancel_after:
            enough.set()

    t0 = time.monotonic()
    client.send_goal(part("Goal")(order=order), active_cb=lambda: emit("active", label=label), feedback_cb=feedback)
    if cancel_after:
        enough.wait(20.0)
        emit("cancel_sent", label=label, feedback=len(received))
        client.cancel_goal()
    finished = client.wait_for_result(rospy.Duration(20.0))
    status = client.get_state() if finished else -1
    result = client.get_result() if finished else None
    emit("result", label=label, status=status,
         status_name=STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else "TIMEOUT",
         text=client.get_goal_status_text() if finished else "", elapsed=time.monotonic() - t0,
         sequence_ok=result is not None and list(result.sequence) == fibonacci(order),
         feedback=len(received), feedback_in_order=received == list(range(len(received))),
         # stock actionlib drops feedback that arrives before send_goal() has stored its goal handle
         # (SimpleActionClient._handle_feedback: ``if not self.gh: return``): the first may go on a loaded machine
         feedback_first=received[0] if received else None,
         feedback_unbroken=bool(received) and received == list(range(received[0], received[0] + len(received))))


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("name")
    ap.add_argument("--order", type=int, default=20)
    ap.add_argument("--cancel-order", type=int, default=5000)
    ap.add_argument("--cancel-after", type=int, default=5)
    ap.add_argument("--wait", type=float, default=30.0)
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("plain_action_client", disable_rosout=True)
    client = actionlib.SimpleActionClient(args.name, fibonacci_action())
    t0 = time.monotonic()
    if not client.wait_for_server(rospy.Duration(args.wait)):
        emit("unavailable", elapsed=time.monotonic() - t0)
        return 1
    emit("available", elapsed=time.monotonic() - t0)
    run_goal(client, "fib", args.order)
    run_goal(client, "cancel", args.cancel_order, args.cancel_after)
    emit("done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
