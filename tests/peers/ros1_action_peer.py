"""A ROS 1 action server or client with stock actionlib (/usr/bin/python3, no micros_rt), or the micros_rt process
between ROS 1 and ROS 2 (``bridge``, project venv). Type: test_msgs/Fibonacci, built at run time
(ros1_action_types.py). One JSON event per line.

    ros1_action_peer.py serve --name /r1/fib [--period 0.005] [--die-after K]
    ros1_action_peer.py call --plan '[{"label": "fib", "name": "/r2/fib", "order": 100, "wait": 20}]'
    ros1_action_peer.py bridge --to-ros2 /r1/fib --from-ros2 /r2/fib [--accept-timeout 2]

serve: a SimpleActionServer; a goal of order N publishes N feedback messages, one per ``period``, then succeeds with
fibonacci(N); a cancel preempts it at the next feedback. Events: "ready"; "goal" {order}; "cancel_received" {t}
(time.time() when actionlib handed the cancel over); "finished" {status, feedback}. ``--die-after K``: the process
kills itself (SIGKILL) after K feedback messages of a goal.

call, per step (a SimpleActionClient per name): "available" or "unavailable" (wait_for_server), then "result"
{label, status, status_name, text, sequence_ok, feedback, feedback_in_order, elapsed}; a step with "cancel_after": K
cancels after K feedback messages and reports "cancel_sent" {t} (time.time() just before the cancel). "timeout"
bounds the wait for the result (then "result" has status_name "TIMEOUT"). Finally "done".

bridge: micros_rt's NodeHandle.offer_action_to_ros2 (each --to-ros2 name, whose ROS 1 server must come up first)
and offer_ros2_action (each --from-ros2 name; "--expect" names the ones whose ROS 2 server is waited for). Events:
"wrong_type" {message} (offering a goal class instead of the action), "ready", then for each --call-in-process name
a goal of order 100 from stock actionlib's SimpleActionClient in this very process: "in_process_result" {status,
text, feedback, feedback_in_order, sequence_ok}; then "stats" {name: statistics()} whenever they change.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from typing import Any, Dict, List

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import rospy  # noqa: E402

from ros1_action_types import fibonacci, fibonacci_action, part  # noqa: E402

STATUS_NAMES = ("PENDING", "ACTIVE", "PREEMPTED", "SUCCEEDED", "ABORTED", "REJECTED", "PREEMPTING", "RECALLING",
                "RECALLED", "LOST")


def emit(event: str, **kw: Any) -> None:
    # one write per line: a log line from another thread must not land inside it
    sys.stdout.write(json.dumps({"event": event, **kw}, default=repr) + "\n")
    sys.stdout.flush()


def serve(args: argparse.Namespace) -> None:
    import actionlib  # type: ignore[import-untyped]

    rospy.init_node("stock_action_server", anonymous=True)
    Feedback, Result = part("Feedback"), part("Result")
    server: Any = None

    def on_cancel() -> None:
        emit("cancel_received", t=time.time())

    def execute(goal: Any) -> None:
        emit("goal", order=goal.order)
        sent = 0
        for i in range(goal.order):
            if server.is_preempt_requested():
                server.set_preempted(Result(sequence=fibonacci(i)), "preempted by the client's cancel")
                emit("finished", status="PREEMPTED", feedback=sent)
                return
            server.publish_feedback(Feedback(sequence=[i]))
            sent += 1
            if args.die_after and sent >= args.die_after:
                os.kill(os.getpid(), signal.SIGKILL)
            time.sleep(args.period)
        server.set_succeeded(Result(sequence=fibonacci(goal.order)), "done")
        emit("finished", status="SUCCEEDED", feedback=sent)

    server = actionlib.SimpleActionServer(args.name, fibonacci_action(), execute_cb=execute, auto_start=False)
    server.register_preempt_callback(on_cancel)
    server.start()
    emit("ready")
    end = time.monotonic() + args.seconds
    while not rospy.is_shutdown() and time.monotonic() < end:
        time.sleep(0.1)
    emit("done")


def call(args: argparse.Namespace) -> None:
    import actionlib

    rospy.init_node("stock_action_client", anonymous=True)
    Goal = part("Goal")
    clients: Dict[str, Any] = {}
    for step in json.loads(args.plan):
        label, name = step.get("label", step["name"]), step["name"]
        if name not in clients:
            clients[name] = actionlib.SimpleActionClient(name, fibonacci_action())
        client = clients[name]
        t0 = time.monotonic()
        if not client.wait_for_server(rospy.Duration(step.get("wait", 10.0))):
            emit("unavailable", label=label, elapsed=time.monotonic() - t0)
            continue
        emit("available", label=label, elapsed=time.monotonic() - t0)
        received: List[int] = []
        enough = threading.Event()
        cancel_after = step.get("cancel_after")

        def feedback(fb: Any, received: List[int] = received, enough: threading.Event = enough,
                     cancel_after: Any = cancel_after) -> None:
            received.append(fb.sequence[0] if fb.sequence else -1)
            if cancel_after is not None and len(received) >= cancel_after:
                enough.set()

        t0 = time.monotonic()
        client.send_goal(Goal(order=step["order"]), feedback_cb=feedback)
        if cancel_after is not None:
            enough.wait(step.get("timeout", 20.0))
            emit("cancel_sent", label=label, t=time.time(), feedback=len(received))
            client.cancel_goal()
        finished = client.wait_for_result(rospy.Duration(step.get("timeout", 20.0)))
        status = client.get_state() if finished else -1
        result = client.get_result() if finished else None
        sequence = list(result.sequence) if result is not None else None
        emit("result", label=label, status=status,
             status_name=STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else "TIMEOUT",
             text=client.get_goal_status_text() if finished else "", elapsed=time.monotonic() - t0,
             sequence_ok=sequence == fibonacci(step["order"]), sequence_len=len(sequence or []),
             feedback=len(received), feedback_in_order=received == list(range(len(received))))
    emit("done")


def bridge(args: argparse.Namespace) -> None:
    import micros_rt

    micros_rt.init_node("mrt_action_bridge", anonymous=True)
    nh = micros_rt.NodeHandle()
    action = fibonacci_action()
    offers: Dict[str, Any] = {}
    for name in args.to_ros2:
        offer = nh.offer_action_to_ros2(name, action, accept_timeout=args.accept_timeout)
        if not offer.wait_for_server(30.0):
            emit("error", message=f"no ROS 1 server at {name}")
        offers[name] = offer
    for name in args.from_ros2:
        offers[name] = nh.offer_ros2_action(name, action, accept_timeout=args.accept_timeout)
    for name in args.expect:
        if not offers[name].wait_for_ros2_server(30.0):
            emit("error", message=f"no ROS 2 server of {name} discovered")
    try:   # a class that is not an action: refused at once, in words
        nh.offer_ros2_action("wrong_type", part("Goal"))
    except TypeError as exc:
        emit("wrong_type", message=str(exc))
    emit("ready", types={name: offer.ros2_type for name, offer in offers.items()})
    for name in args.call_in_process:   # stock actionlib's client in this micros_rt process, on an offered name
        import actionlib

        received: List[int] = []
        client = actionlib.SimpleActionClient(name, action)
        t0 = time.monotonic()
        client.wait_for_server(rospy.Duration(20.0))
        client.send_goal(part("Goal")(order=100), feedback_cb=lambda fb: received.append(fb.sequence[0]))
        finished = client.wait_for_result(rospy.Duration(20.0))
        result = client.get_result() if finished else None
        emit("in_process_result", name=name, status=client.get_state() if finished else -1,
             text=client.get_goal_status_text(), feedback=len(received),
             feedback_in_order=received == list(range(len(received))),
             sequence_ok=result is not None and list(result.sequence) == fibonacci(100),
             elapsed=time.monotonic() - t0)
    last: Dict[str, Any] = {}
    end = time.monotonic() + args.seconds
    while not rospy.is_shutdown() and time.monotonic() < end:
        stats = {name: offer.statistics() for name, offer in offers.items()}
        if stats != last:
            emit("stats", stats=stats)
            last = stats
        time.sleep(0.1)
    emit("done")


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="mode", required=True)
    s = sub.add_parser("serve")
    s.add_argument("--name", required=True)
    s.add_argument("--period", type=float, default=0.005)
    s.add_argument("--die-after", type=int, default=0)
    s.add_argument("--seconds", type=float, default=120.0)
    c = sub.add_parser("call")
    c.add_argument("--plan", required=True)
    b = sub.add_parser("bridge")
    b.add_argument("--to-ros2", nargs="*", default=[])
    b.add_argument("--from-ros2", nargs="*", default=[])
    b.add_argument("--expect", nargs="*", default=[])
    b.add_argument("--accept-timeout", type=float, default=5.0)
    b.add_argument("--call-in-process", nargs="*", default=[])
    b.add_argument("--seconds", type=float, default=120.0)
    args = parser.parse_args()
    {"serve": serve, "call": call, "bridge": bridge}[args.mode](args)


if __name__ == "__main__":
    main()
