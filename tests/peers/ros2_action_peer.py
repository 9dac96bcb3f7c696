"""ROS 2 (rclpy, Fast DDS) action server or client for tests: test_msgs/action/Fibonacci. Run ONLY with
.venv-ros2/bin/python. Environment as ros2_peer.py (loopback-only Fast DDS, this run's ROS_DOMAIN_ID).

    ros2_action_peer.py serve --actions '[{"name": "/r2/fib"}, {"name": "/r2/silent", "mode": "silent"}]'
    ros2_action_peer.py call --plan '[{"label": "fib", "name": "/r1/fib", "order": 100, "wait": 20}]'

serve --clock also publishes /clock (rosgraph_msgs/msg/Clock, 2000 s + n * 0.1 s, every 50 ms), as a simulator.

The same protocol and events as tests/peers/ros1_action_peer.py: a goal of order N gets N feedback messages (the
i-th ``sequence == [i]``, one per --period), then fibonacci(N). Server modes: "normal"; "silent" (the goal callback
never answers); "die" (the process kills itself with SIGKILL after --die-after feedback messages). Events: "ready",
"goal" {name, order}, "cancel_received" {name, t}, "finished" {name, status, feedback}. Client steps: "available" /
"unavailable", "cancel_sent" {t} for a step with "cancel_after", "result" {label, status, status_name,
sequence_ok, feedback, feedback_in_order, elapsed}, then "done". Status names are action_msgs/GoalStatus's, plus
"REJECTED" (the goal response said no) and "TIMEOUT". A step's "goal_durability": "transient_local" makes a client
whose goal no server can answer (its goal response reader matches no volatile writer).
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

import rclpy
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse, get_action_names_and_types
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci

STATUS_NAMES = ("UNKNOWN", "ACCEPTED", "EXECUTING", "CANCELING", "SUCCEEDED", "CANCELED", "ABORTED")
#: set when the peer stops: a "silent" goal callback returns then, so that the process exits cleanly
STOP = threading.Event()


def emit(event: str, **kw: Any) -> None:
    # one write per line: a log line from another thread must not land inside it
    sys.stdout.write(json.dumps({"event": event, **kw}, default=repr) + "\n")
    sys.stdout.flush()


def fibonacci(n: int) -> List[int]:
    seq, a, b = [], 0, 1
    for _ in range(n):
        seq.append(a)
        a, b = b, (a + b) % (2 ** 31 - 1)
    return seq


def serve(args: argparse.Namespace, node: Any) -> None:
    group = ReentrantCallbackGroup()
    for spec in json.loads(args.actions):
        name, mode = spec["name"], spec.get("mode", "normal")

        def on_goal(request: Any, name: str = name, mode: str = mode) -> GoalResponse:
            emit("goal", name=name, order=request.order)
            if mode == "silent":
                STOP.wait(3600)
                return GoalResponse.REJECT
            return GoalResponse.ACCEPT

        def on_cancel(handle: Any, name: str = name) -> CancelResponse:
            emit("cancel_received", name=name, t=time.time())
            return CancelResponse.ACCEPT

        def execute(handle: Any, name: str = name, mode: str = mode) -> Any:
            order, sent = handle.request.order, 0
            for i in range(order):
                if handle.is_cancel_requested:
                    handle.canceled()
                    emit("finished", name=name, status="CANCELED", feedback=sent)
                    return Fibonacci.Result(sequence=fibonacci(i))
                handle.publish_feedback(Fibonacci.Feedback(sequence=[i]))
                sent += 1
                if mode == "die" and sent >= args.die_after:
                    os.kill(os.getpid(), signal.SIGKILL)
                time.sleep(args.period)
            handle.succeed()
            emit("finished", name=name, status="SUCCEEDED", feedback=sent)
            return Fibonacci.Result(sequence=fibonacci(order))

        # feedback kept for a slow reader (rclpy's default depth is 10: at 200 Hz on a loaded host the writer
        # overwrote feedback not yet acknowledged, 94 of 100 once); the readers here are as deep
        ActionServer(node, Fibonacci, name, execute_callback=execute, goal_callback=on_goal,
                     cancel_callback=on_cancel, callback_group=group,
                     feedback_pub_qos_profile=QoSProfile(depth=1000))
    if args.clock:
        # a simulator's clock: rosgraph_msgs/msg/Clock on /clock, 2000 s + n * 0.1 s, every 50 ms
        from rosgraph_msgs.msg import Clock

        clock_pub = node.create_publisher(Clock, "/clock", 10)
        ticks = [0]

        def tick() -> None:
            n = ticks[0]
            ticks[0] += 1
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = 2000 + n // 10, (n % 10) * 100_000_000
            clock_pub.publish(msg)

        node.create_timer(0.05, tick, callback_group=group)
    emit("ready")


def call(args: argparse.Namespace, node: Any) -> None:
    clients: Dict[str, Any] = {}
    for step in json.loads(args.plan):
        label, name = step.get("label", step["name"]), step["name"]
        deaf = step.get("goal_durability") == "transient_local"
        if deaf:
            # a goal response reader no server's (volatile) writer matches: the server takes the goal and can never
            # answer it; the client is never "ready", so it sends once the action is in the graph
            client = ActionClient(node, Fibonacci, name, goal_service_qos_profile=QoSProfile(
                depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        elif name not in clients:
            # every feedback message counts here: a reader deeper than rclpy's default 10, as the CPU is shared
            clients[name] = ActionClient(node, Fibonacci, name, feedback_sub_qos_profile=QoSProfile(depth=1000))
        client = client if deaf else clients[name]
        t0 = time.monotonic()
        if deaf:
            while name not in dict(get_action_names_and_types(node)) and time.monotonic() - t0 < step.get("wait", 10):
                time.sleep(0.05)
            # a goal every 2 s (the first ones may go before the goal writer matched the server's reader)
            futures = []
            while time.monotonic() - t0 < step.get("timeout", 20.0):
                futures.append(client.send_goal_async(Fibonacci.Goal(order=step["order"])))
                time.sleep(2.0)
            answered_goals = sum(1 for f in futures if f.done())
            emit("result", label=label, status=-1, status_name="TIMEOUT" if not answered_goals else "ANSWERED",
                 goals=len(futures), answered=answered_goals, elapsed=time.monotonic() - t0)
            continue
        elif not client.wait_for_server(timeout_sec=step.get("wait", 10.0)):
            emit("unavailable", label=label, elapsed=time.monotonic() - t0)
            continue
        emit("available", label=label, elapsed=time.monotonic() - t0)
        timeout = step.get("timeout", 20.0)
        received: List[int] = []
        enough = threading.Event()
        cancel_after = step.get("cancel_after")

        def feedback(message: Any, received: List[int] = received, enough: threading.Event = enough,
                     cancel_after: Any = cancel_after) -> None:
            seq = message.feedback.sequence
            received.append(seq[0] if len(seq) else -1)
            if cancel_after is not None and len(received) >= cancel_after:
                enough.set()

        t0 = time.monotonic()
        answered = threading.Event()
        goal_future = client.send_goal_async(Fibonacci.Goal(order=step["order"]), feedback_callback=feedback)
        goal_future.add_done_callback(lambda _f, answered=answered: answered.set())
        status_name, status, sequence = "TIMEOUT", -1, None
        if answered.wait(timeout):
            handle = goal_future.result()
            if not handle.accepted:
                status_name = "REJECTED"
            else:
                if cancel_after is not None:
                    enough.wait(timeout)
                    emit("cancel_sent", label=label, t=time.time(), feedback=len(received))
                    handle.cancel_goal_async()
                done = threading.Event()
                result_future = handle.get_result_async()
                result_future.add_done_callback(lambda _f, done=done: done.set())
                if done.wait(timeout):
                    response = result_future.result()
                    status, sequence = int(response.status), list(response.result.sequence)
                    status_name = STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else str(status)
                    # rclpy may hand over the result before feedback taken in the same batch: let it through
                    deadline = time.monotonic() + 1.0
                    while len(received) < step["order"] and time.monotonic() < deadline and cancel_after is None:
                        time.sleep(0.01)
        emit("result", label=label, status=status, status_name=status_name, elapsed=time.monotonic() - t0,
             sequence_ok=sequence == fibonacci(step["order"]), sequence_len=len(sequence or []),
             feedback=len(received), feedback_in_order=received == list(range(len(received))))
    emit("done")


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="mode", required=True)
    s = sub.add_parser("serve")
    s.add_argument("--actions", required=True)
    s.add_argument("--period", type=float, default=0.005)
    s.add_argument("--die-after", type=int, default=5)
    s.add_argument("--seconds", type=float, default=120.0)
    s.add_argument("--clock", action="store_true", help="also publish /clock (rosgraph_msgs/msg/Clock)")
    c = sub.add_parser("call")
    c.add_argument("--plan", required=True)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node(f"ros2_action_{args.mode}_{os.getpid()}")
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    finished = threading.Event()

    def work() -> None:
        try:
            if args.mode == "serve":
                serve(args, node)
                STOP.wait(args.seconds)
                emit("done")
            else:
                call(args, node)
        finally:
            finished.set()

    # the executor spins in the main thread: a clean exit there lets Fast DDS remove its /dev/shm segments
    threading.Thread(target=work, daemon=True).start()
    try:
        while not finished.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        STOP.set()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
