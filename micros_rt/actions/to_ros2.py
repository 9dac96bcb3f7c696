"""A ROS 1 action server offered to ROS 2 action clients (:meth:`micros_rt.NodeHandle.offer_action_to_ros2`).

The ROS 2 helper (:mod:`micros_rt.services.ros2_helper`) hosts an rclpy ActionServer of the same name. Each goal a
ROS 2 client sends reaches this process, which sends it on to the ROS 1 server with actionlib's own
``actionlib.ActionClient``; the ROS 1 server's verdict (its first status: PENDING or ACTIVE accepts, REJECTED
rejects), its feedback and its result go back to the helper, which answers the ROS 2 client. A cancel from the ROS 2
client becomes actionlib's cancel of that goal.
"""

from __future__ import annotations

import functools
import threading
import time
from typing import Any, Callable, Dict, Optional

import actionlib  # type: ignore[import-untyped]
import rospy
from actionlib_msgs.msg import GoalStatusArray  # type: ignore[import-untyped]

from ..log import nonblocking_logger
from ..services.gateway import GONE, Ros2Gateway, Ros2Unavailable
from ..services.helper_protocol import A_DONE, A_FEEDBACK, A_VERDICT, G_CANCEL, G_GOAL
from .mapping import ROS1, ActionMapping, action_mapping, ros1_to_ros2_status, status_name

__all__ = ["ActionToRos2", "ACCEPT_TIMEOUT"]

_log = nonblocking_logger("rosout.micros_rt.actions")

#: seconds a ROS 1 server may take to acknowledge a goal before the ROS 2 client's goal is rejected
ACCEPT_TIMEOUT = 5.0
_WATCH_PERIOD = 0.1
# actionlib's CommState (actionlib.action_client)
_WAITING_FOR_GOAL_ACK, _DONE = 0, 7


class _Goal:
    __slots__ = ("key", "goal", "handle", "deadline", "decided", "done", "cancel_at")

    def __init__(self, key: int, goal: Any, deadline: float) -> None:
        self.key = key
        self.goal = goal          # kept until it is sent: a goal waits for its ROS 1 server until the deadline
        self.handle: Any = None
        self.deadline = deadline
        self.decided = False
        self.done = False
        self.cancel_at: Optional[float] = None


class ActionToRos2:
    """What :meth:`micros_rt.NodeHandle.offer_action_to_ros2` returns: the ROS 1 action server at
    ``resolved_name``, reachable by ROS 2 action clients. ``shutdown()`` withdraws it from ROS 2 (goals in flight
    are cancelled on the ROS 1 server); ``statistics()`` counts goals, feedback and drops."""

    def __init__(self, resolved_name: str, action_class: Any, gateway: Callable[[], Ros2Gateway], *,
                 ros2_type: Optional[str] = None, accept_timeout: float = ACCEPT_TIMEOUT) -> None:
        if not accept_timeout > 0:
            raise ValueError(f"accept_timeout must be a positive number of seconds, got {accept_timeout!r}")
        self.resolved_name = resolved_name
        self.mapping: ActionMapping = action_mapping(action_class, ros2_type)
        self.accept_timeout = float(accept_timeout)
        self.closed = False
        self._lock = threading.Lock()
        self._goals: Dict[int, _Goal] = {}
        self._stats = {"goals": 0, "accepted": 0, "rejected": 0, "succeeded": 0, "canceled": 0, "aborted": 0,
                       "feedback": 0, "feedback_dropped": 0, "cancels": 0}
        self._client = actionlib.ActionClient(resolved_name, action_class)
        # the same topic as the ActionClient's status subscriber (rospy shares one connection per topic): its
        # connection count drops as soon as the server's process is gone
        self._status = rospy.Subscriber(resolved_name + "/status", GoalStatusArray, self._on_status)
        self._status_seen = False
        try:
            self._gateway = gateway()
            self._gateway.serve_action(resolved_name, self.mapping.ros2_type, self._on_frame)
        except Exception:
            self._status.unregister()
            raise
        threading.Thread(target=self._watch, name=f"micros_rt action {resolved_name}", daemon=True).start()

    # -- the ROS 1 server -----------------------------------------------------------------------------------------
    def _on_status(self, msg: Any) -> None:
        self._status_seen = True

    def server_present(self) -> bool:
        """Whether a ROS 1 action server of the name is connected to this node: its status arrives, and it has
        subscribed to this node's goals and cancels (a goal published before that would be lost)."""
        return (self._status_seen and self._status.get_num_connections() > 0
                and self._client.pub_goal.get_num_connections() > 0
                and self._client.pub_cancel.get_num_connections() > 0)

    def wait_for_server(self, timeout: float) -> bool:
        """Block until the ROS 1 server is connected (True) or ``timeout`` seconds passed (False)."""
        deadline = time.monotonic() + timeout
        while not self.server_present():
            if time.monotonic() >= deadline or rospy.is_shutdown():
                return False
            time.sleep(0.02)
        return True

    # -- frames from the helper (the socket's thread) -------------------------------------------------------------
    def _on_frame(self, op: int, key: int, meta: Dict[str, Any], body: bytes) -> None:
        if op == G_GOAL:
            self._goal(key, body)
        elif op == G_CANCEL:
            with self._lock:
                entry = self._goals.get(key)
            if entry is None:
                return
            self._count("cancels")
            entry.cancel_at = time.monotonic()
            if entry.handle is not None:
                entry.handle.cancel()
            elif self._end(entry):   # never sent: nothing to cancel on ROS 1
                self._reject(entry.key, "cancelled before a ROS 1 action server was there")
        elif op == GONE:
            self._abandon(f"the ROS 2 helper is gone ({meta.get('error')})")

    def _count(self, what: str) -> int:
        with self._lock:
            self._stats[what] += 1
            return self._stats[what]

    def _end(self, entry: _Goal) -> bool:
        """Take the goal out of the books; False when it was already."""
        with self._lock:
            if entry.done:
                return False
            entry.decided = entry.done = True
            self._goals.pop(entry.key, None)
            return True

    def _goal(self, key: int, body: bytes) -> None:
        self._count("goals")
        try:
            goal = self.mapping.decode_goal(body)
        except Exception as exc:
            self._reject(key, f"the goal does not decode as {self.mapping.goal_class._type}: {exc}")
            return
        if self.closed:
            self._reject(key, "the offer was shut down")
            return
        entry = _Goal(key, goal, time.monotonic() + self.accept_timeout)
        with self._lock:
            self._goals[key] = entry
        if self.server_present():
            self._send_goal(entry)
        # else the watch sends it once the ROS 1 server is connected, or rejects it at the deadline

    def _send_goal(self, entry: _Goal) -> None:
        goal, entry.goal = entry.goal, None
        if goal is None:
            return
        # the handle must be kept: actionlib tracks a goal only while a handle of it lives
        entry.handle = self._client.send_goal(goal, functools.partial(self._transition, entry),
                                              functools.partial(self._feedback, entry))

    def _send(self, op: int, key: int, meta: Dict[str, Any], body: bytes = b"") -> None:
        try:
            self._gateway.send_action(op, key, {"name": self.resolved_name, **meta}, body)
        except Ros2Unavailable:
            pass  # the helper is gone: every goal is abandoned through GONE

    def _reject(self, key: int, why: str) -> None:
        self._count("rejected")
        _log.warning("micros_rt: action %s: a ROS 2 client's goal is rejected: %s (ROS 2 goal responses carry no "
                     "reason)", self.resolved_name, why)
        self._send(A_VERDICT, key, {"accepted": False})

    # -- actionlib's callbacks (rospy's threads) ------------------------------------------------------------------
    def _transition(self, entry: _Goal, handle: Any) -> None:
        comm = handle.get_comm_state()
        if comm == _WAITING_FOR_GOAL_ACK or entry.done:
            return
        status = handle.get_goal_status()
        if not entry.decided:
            entry.decided = True
            if status == ROS1.REJECTED:
                if self._end(entry):
                    self._reject(entry.key, f"the ROS 1 action server rejected it: "
                                            f"{handle.get_goal_status_text() or 'no reason given'}")
                return
            self._count("accepted")
            self._send(A_VERDICT, entry.key, {"accepted": True})
        if comm == _DONE:
            self._finish(entry, status, handle.get_result(), handle.get_goal_status_text())

    def _feedback(self, entry: _Goal, handle: Any, feedback: Any) -> None:
        if entry.done:
            self._drop_feedback("its goal is over")
            return
        try:
            body = self.mapping.encode_feedback(feedback)
        except Exception as exc:
            self._drop_feedback(f"it does not serialize: {exc}")
            return
        self._count("feedback")
        self._send(A_FEEDBACK, entry.key, {}, body)

    def _drop_feedback(self, why: str) -> None:
        n = self._count("feedback_dropped")
        if n == 1 or n % 100 == 0:
            _log.warning("micros_rt: action %s: a feedback of the ROS 1 server was dropped because %s (%d so far)",
                         self.resolved_name, why, n)

    def _finish(self, entry: _Goal, status: int, result: Any, text: str) -> None:
        if not self._end(entry):
            return
        ros2 = ros1_to_ros2_status(status)
        outcome = {ROS1.SUCCEEDED: "succeeded", ROS1.PREEMPTED: "canceled", ROS1.RECALLED: "canceled"}
        self._count(outcome.get(status, "aborted"))
        body = b""
        if result is not None:
            try:
                body = self.mapping.encode_result(result)
            except Exception as exc:
                _log.warning("micros_rt: action %s: the ROS 1 server's result does not serialize (%s); the ROS 2 "
                             "client gets an empty one", self.resolved_name, exc)
        if status != ROS1.SUCCEEDED:
            _log.info("micros_rt: action %s: a ROS 2 client's goal ended %s on the ROS 1 server (%s): %s",
                      self.resolved_name, status_name(status, "ROS 1"), status_name(ros2, "ROS 2"),
                      text or "no text")
        self._send(A_DONE, entry.key, {"status": ros2}, body)

    # -- the watch: goals never acknowledged, servers gone ------------------------------------------------------
    def _watch(self) -> None:
        while not self.closed and not rospy.is_shutdown():
            time.sleep(_WATCH_PERIOD)
            now = time.monotonic()
            present = self.server_present()
            with self._lock:
                goals = list(self._goals.values())
            for entry in goals:
                if not entry.decided and entry.goal is not None and present:
                    self._send_goal(entry)
                elif not entry.decided and now >= entry.deadline:
                    if not self._end(entry):
                        continue
                    if entry.handle is not None:
                        entry.handle.cancel()
                    self._reject(entry.key, (
                        f"the ROS 1 action server at {self.resolved_name} did not acknowledge it within "
                        f"{self.accept_timeout:g} s") if entry.handle is not None else (
                        f"no ROS 1 action server at {self.resolved_name} was connected to this node within "
                        f"{self.accept_timeout:g} s"))
                elif entry.decided and not present:
                    _log.warning("micros_rt: action %s: the ROS 1 action server went away during a ROS 2 client's "
                                 "goal; the goal ends ABORTED", self.resolved_name)
                    self._finish(entry, ROS1.LOST, None, "the ROS 1 action server went away during the goal")

    def _abandon(self, why: str) -> None:
        with self._lock:
            goals = list(self._goals.values())
        goals = [g for g in goals if self._end(g)]
        for entry in goals:
            if entry.handle is not None:
                entry.handle.cancel()
        if goals:
            _log.warning("micros_rt: action %s: %s; %d goal(s) of ROS 2 clients cancelled on the ROS 1 server",
                         self.resolved_name, why, len(goals))

    # -- public -------------------------------------------------------------------------------------------------
    @property
    def ros2_type(self) -> str:
        """The ROS 2 action type ROS 2 clients use (``test_msgs/action/Fibonacci``)."""
        return self.mapping.ros2_type

    def statistics(self) -> Dict[str, int]:
        """Goals from ROS 2 clients and what became of them, feedback forwarded and dropped, cancels."""
        with self._lock:
            return dict(self._stats)

    def shutdown(self) -> None:
        """Withdraw the action from ROS 2; goals in flight are cancelled on the ROS 1 server. Harmless twice."""
        if self.closed:
            return
        self.closed = True
        self._gateway.withdraw_action(self.resolved_name)
        self._abandon("the offer was shut down")
        self._status.unregister()
        self._client.stop()

    close = shutdown

    def __enter__(self) -> "ActionToRos2":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    def __repr__(self) -> str:
        return f"<ActionToRos2 {self.resolved_name} ({self.mapping.ros_type} -> {self.mapping.ros2_type})>"
