"""A ROS 2 action server offered to ROS 1 action clients (:meth:`micros_rt.NodeHandle.offer_ros2_action`).

This process serves the action to ROS 1 with actionlib's own ``actionlib.ActionServer`` (the goal, cancel, status,
feedback and result topics of the name, through the master); the ROS 2 helper
(:mod:`micros_rt.services.ros2_helper`) holds an rclpy ActionClient of the same name. A ROS 1 client's goal is
sent on to the ROS 2 server, and is accepted or rejected on ROS 1 when the ROS 2 server answers; the feedback and
the result come back the same way, and a ROS 1 cancel becomes an rclpy cancel of that goal. Every refusal and
failure reaches the ROS 1 client in words, as its goal status text.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable, Dict, Optional

import actionlib  # type: ignore[import-untyped]
import rospy

from ..log import nonblocking_logger
from ..services.gateway import GONE, Ros2Gateway, Ros2Unavailable
from ..services.helper_protocol import A_CANCEL, A_FORGET, A_SEND, G_ACCEPTED, G_FEEDBACK, G_RESULT
from .mapping import ROS2, ActionMapping, action_mapping, status_name

__all__ = ["ActionFromRos2", "FEEDBACK_GRACE"]

_log = nonblocking_logger("rosout.micros_rt.actions")

#: seconds between the last feedback and the result on ROS 1: rclpy hands a result taken in one batch with
#: feedback over first, and actionlib clients drop feedback that comes after the result
FEEDBACK_GRACE = 0.02
_WATCH_PERIOD = 0.1


class _Goal:
    __slots__ = ("key", "handle", "deadline", "decided", "done", "last_feedback", "cancel_at")

    def __init__(self, key: int, handle: Any, deadline: float) -> None:
        self.key = key
        self.handle = handle
        self.deadline = deadline
        self.decided = False
        self.done = False
        self.last_feedback = 0.0
        self.cancel_at: Optional[float] = None


class ActionFromRos2:
    """What :meth:`micros_rt.NodeHandle.offer_ros2_action` returns: an actionlib server at ``resolved_name`` in this
    process whose goals run on the ROS 2 action server of that name. ``wait_for_ros2_server(t)`` waits for DDS
    discovery of it; ``shutdown()`` withdraws the ROS 1 server; ``statistics()`` counts goals, feedback and drops."""

    def __init__(self, resolved_name: str, action_class: Any, gateway: Callable[[], Ros2Gateway], *,
                 ros2_type: Optional[str] = None, accept_timeout: float = 5.0) -> None:
        if not accept_timeout > 0:
            raise ValueError(f"accept_timeout must be a positive number of seconds, got {accept_timeout!r}")
        self.resolved_name = resolved_name
        self.mapping: ActionMapping = action_mapping(action_class, ros2_type)
        self.accept_timeout = float(accept_timeout)
        self.closed = False
        self._lock = threading.Lock()
        self._goals: Dict[int, _Goal] = {}
        self._by_id: Dict[str, int] = {}
        self._stats = {"goals": 0, "accepted": 0, "rejected": 0, "succeeded": 0, "canceled": 0, "aborted": 0,
                       "feedback": 0, "feedback_dropped": 0, "cancels": 0}
        self._gateway = gateway()
        self._gateway.action_client(resolved_name, self.mapping.ros2_type, self._on_frame)
        self._server = actionlib.ActionServer(resolved_name, action_class, self._on_goal, self._on_cancel,
                                              auto_start=False)
        self._server.start()
        threading.Thread(target=self._watch, name=f"micros_rt action {resolved_name}", daemon=True).start()

    def _count(self, what: str) -> int:
        with self._lock:
            self._stats[what] += 1
            return self._stats[what]

    # -- actionlib's callbacks (rospy's threads, under the ActionServer's lock) ------------------------------------
    def _on_goal(self, handle: Any) -> None:
        self._count("goals")
        try:
            body = self.mapping.encode_goal(handle.get_goal())
        except Exception as exc:
            self._count("rejected")
            handle.set_rejected(None, f"action {self.resolved_name}: the goal does not serialize for ROS 2: {exc}")
            return
        key = self._gateway.new_key()
        entry = _Goal(key, handle, time.monotonic() + self.accept_timeout)
        with self._lock:
            self._goals[key] = entry
            self._by_id[handle.get_goal_id().id] = key
        try:
            self._gateway.send_action(A_SEND, key, {"name": self.resolved_name}, body)
        except Ros2Unavailable as exc:
            self._end(entry)
            self._count("rejected")
            handle.set_rejected(None, f"action {self.resolved_name}: ROS 2 is unreachable: {exc}")

    def _on_cancel(self, handle: Any) -> None:
        with self._lock:
            key = self._by_id.get(handle.get_goal_id().id)
            entry = self._goals.get(key) if key is not None else None
        if entry is None:
            return
        entry.cancel_at = time.monotonic()
        self._count("cancels")
        try:
            self._gateway.send_action(A_CANCEL, entry.key, {"name": self.resolved_name})
        except Ros2Unavailable:
            pass  # GONE ends the goal

    # -- frames from the helper (the socket's thread) -------------------------------------------------------------
    def _on_frame(self, op: int, key: int, meta: Dict[str, Any], body: bytes) -> None:
        if op == GONE:
            for gone in self._take_all():
                self._fail(gone, f"the ROS 2 helper is gone ({meta.get('error')})")
            return
        with self._lock:
            entry = self._goals.get(key)
        if entry is None or entry.done:
            if op == G_FEEDBACK:
                self._drop_feedback("its goal is over")
            return
        if op == G_ACCEPTED:
            entry.decided = True
            if meta.get("accepted"):
                self._count("accepted")
                entry.handle.set_accepted("accepted by the ROS 2 action server")
            else:
                self._end(entry)
                self._count("rejected")
                entry.handle.set_rejected(None, f"action {self.resolved_name}: {meta.get('error', 'rejected')}")
        elif op == G_FEEDBACK:
            try:
                feedback = self.mapping.decode_feedback(body)
            except Exception as exc:
                self._drop_feedback(f"it does not decode as {self.mapping.feedback_class._type}: {exc}")
                return
            self._count("feedback")
            entry.last_feedback = time.monotonic()
            entry.handle.publish_feedback(feedback)
        elif op == G_RESULT:
            wait = entry.last_feedback + FEEDBACK_GRACE - time.monotonic()
            if wait > 0:   # feedback taken with the result in one batch comes after it: let it through first
                threading.Timer(wait, self._finish, args=(entry, meta, body)).start()
            else:
                self._finish(entry, meta, body)

    def _drop_feedback(self, why: str) -> None:
        n = self._count("feedback_dropped")
        if n == 1 or n % 100 == 0:
            _log.warning("micros_rt: action %s: a feedback of the ROS 2 server was dropped because %s (%d so far)",
                         self.resolved_name, why, n)

    def _end(self, entry: _Goal) -> bool:
        """Take the goal out of the books; False when it was already."""
        with self._lock:
            if entry.done:
                return False
            entry.done = True
            self._goals.pop(entry.key, None)
            self._by_id.pop(entry.handle.get_goal_id().id, None)
            return True

    def _take_all(self) -> "list[_Goal]":
        with self._lock:
            goals = [g for g in self._goals.values() if not g.done]
        return [g for g in goals if self._end(g)]

    def _finish(self, entry: _Goal, meta: Dict[str, Any], body: bytes) -> None:
        if not self._end(entry):
            return
        status = int(meta.get("status", ROS2.ABORTED))
        error = meta.get("error")
        try:
            result = self.mapping.decode_result(body) if body else self.mapping.result_class()
        except Exception as exc:
            result, status = self.mapping.result_class(), ROS2.ABORTED
            error = f"the ROS 2 server's result does not decode as {self.mapping.result_class._type}: {exc}"
        handle = entry.handle
        if not entry.decided:    # never accepted on ROS 1: only a rejection is possible there
            self._count("rejected")
            handle.set_rejected(result, f"action {self.resolved_name}: {error or 'the ROS 2 server ended the goal'}")
        elif status == ROS2.SUCCEEDED:
            self._count("succeeded")
            handle.set_succeeded(result, "succeeded on the ROS 2 action server")
        elif status == ROS2.CANCELED and entry.cancel_at is not None:
            self._count("canceled")
            handle.set_canceled(result, "canceled on the ROS 2 action server")
        else:
            self._count("aborted")
            why = error or (f"the ROS 2 action server canceled the goal, which no ROS 1 client asked for"
                            if status == ROS2.CANCELED else
                            f"the ROS 2 action server ended the goal {status_name(status, 'ROS 2')}")
            handle.set_aborted(result, f"action {self.resolved_name}: {why}")

    def _fail(self, entry: _Goal, why: str) -> None:
        text = f"action {self.resolved_name}: {why}"
        if entry.decided:
            self._count("aborted")
            entry.handle.set_aborted(None, text)
        else:
            self._count("rejected")
            entry.handle.set_rejected(None, text)

    # -- the watch: goals the ROS 2 server never answered -------------------------------------------------------
    def _watch(self) -> None:
        while not self.closed and not rospy.is_shutdown():
            time.sleep(_WATCH_PERIOD)
            now = time.monotonic()
            with self._lock:
                late = [g for g in self._goals.values() if not g.decided and not g.done and now >= g.deadline]
            for entry in late:
                if not self._end(entry):
                    continue
                try:
                    self._gateway.send_action(A_FORGET, entry.key, {"name": self.resolved_name})
                except Ros2Unavailable:
                    pass
                self._count("rejected")
                why = (f"the ROS 2 action server did not answer the goal within {self.accept_timeout:g} s"
                       if self.ros2_server_ready() else
                       f"no ROS 2 action server of {self.resolved_name} was discovered within "
                       f"{self.accept_timeout:g} s (ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')})")
                entry.handle.set_rejected(None, f"action {self.resolved_name}: {why}")

    # -- public -------------------------------------------------------------------------------------------------
    @property
    def ros2_type(self) -> str:
        """The ROS 2 action type reached (``test_msgs/action/Fibonacci``)."""
        return self.mapping.ros2_type

    def ros2_server_ready(self) -> bool:
        """Whether the helper has discovered the ROS 2 action server."""
        try:
            return self._gateway.action_server_ready(self.resolved_name)
        except Ros2Unavailable:
            return False

    def wait_for_ros2_server(self, timeout: float) -> bool:
        """Block until the ROS 2 action server is discovered (True) or ``timeout`` seconds passed (False)."""
        deadline = time.monotonic() + timeout
        while not self.ros2_server_ready():
            if time.monotonic() >= deadline or rospy.is_shutdown():
                return False
            time.sleep(0.05)
        return True

    def statistics(self) -> Dict[str, int]:
        """Goals from ROS 1 clients and what became of them, feedback forwarded and dropped, cancels."""
        with self._lock:
            return dict(self._stats)

    def shutdown(self) -> None:
        """Stop serving ROS 1 clients; goals in flight end ABORTED (and are cancelled on ROS 2). Harmless twice."""
        if self.closed:
            return
        self.closed = True
        for entry in self._take_all():
            try:
                self._gateway.send_action(A_CANCEL, entry.key, {"name": self.resolved_name})
            except Ros2Unavailable:
                pass
            self._fail(entry, "the offer was shut down")
        self._gateway.withdraw_action(self.resolved_name)
        self._server.stop()

    close = shutdown

    def __enter__(self) -> "ActionFromRos2":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    def __repr__(self) -> str:
        return f"<ActionFromRos2 {self.resolved_name} ({self.mapping.ros2_type} -> {self.mapping.ros_type})>"
