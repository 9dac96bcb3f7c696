#!/usr/bin/python3
"""A plain rospy script that exercises the rest of rospy: rospy only, no micros_rt import.

Runs as a stock node and unchanged under ``micros-rt run``. First argument, the mode:

* ``argv [--exit N] [ARGS...]``: prints ``{"event": "argv", "argv": sys.argv, "name": __name__,
  "path0": sys.path[0], "file": __file__, "node": ..., "chatter": resolve_name("chatter"), ...}`` after
  ``init_node("plain_probe")`` (so ``__name:=``, ``__ns:=``, ``chatter:=...`` and ``_answer:=...`` show),
  then exits N.
* ``raise``: raises RuntimeError("boom from the script") (exit code 1 and a traceback, as python).
* ``exit-message``: ``sys.exit("bye from the script")`` (message on stderr, exit code 1).
* ``services --topic T``: parameters (set/get/has/delete/search, a private one), a std_srvs/Trigger
  service called through a ServiceProxy, a rospy.Timer, rospy.get_time/get_rostime, rospy.loginfo (to
  /rosout), rospy.wait_for_message on T, on_shutdown and signal_shutdown. One JSON line per check.
* ``latched --topics T1,T2``: subscribes to each latched topic, and once its message came asks
  ``wait_for_message`` (3 s timeout) on it, which rospy answers at once with the latched message.
* ``announce --topic T``: a Publisher with a ``subscriber_listener`` that greets each new subscriber with
  ``peer_publish("welcome N")`` (prints ``peer_subscribe``/``peer_unsubscribe``), ``headers`` and
  ``tcp_nodelay``; spins.
"""

import json
import os
import sys
import threading
import time
from typing import Any, List

import rospy


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps(dict(event=event, **fields)) + "\n")
    sys.stdout.flush()


def mode_argv(args: List[str]) -> None:
    code = int(args[args.index("--exit") + 1]) if "--exit" in args else 0
    rospy.init_node("plain_probe")
    emit("argv", argv=sys.argv, myargv=rospy.myargv(), name=__name__, path0=sys.path[0], file=__file__,
         node=rospy.get_name(), namespace=rospy.get_namespace(), chatter=rospy.resolve_name("chatter"),
         private_param=rospy.get_param("~answer", None))
    sys.exit(code)


def mode_services(args: List[str]) -> None:
    from std_msgs.msg import String
    from std_srvs.srv import Trigger, TriggerResponse

    topic = args[args.index("--topic") + 1] if "--topic" in args else "chatter"
    rospy.init_node("plain_probe")
    shutdown_hooks: List[str] = []
    rospy.on_shutdown(lambda: shutdown_hooks.append("called"))

    rospy.set_param("~answer", 42)
    rospy.set_param("/plain_probe_global", {"a": [1, 2], "b": "x"})
    emit("params", private=rospy.get_param("~answer"), resolved=rospy.resolve_name("~answer"),
         glob=rospy.get_param("/plain_probe_global"), has=rospy.has_param("~answer"),
         default=rospy.get_param("~missing", "fallback"), search=rospy.search_param("plain_probe_global"))
    rospy.delete_param("~answer")
    emit("param_deleted", has=rospy.has_param("~answer"))

    calls: List[int] = []

    def handle(_req: Any) -> Any:
        calls.append(1)
        return TriggerResponse(success=True, message="triggered %d" % len(calls))

    rospy.Service("~trigger", Trigger, handle)
    rospy.wait_for_service("~trigger", timeout=20)
    proxy = rospy.ServiceProxy("~trigger", Trigger)
    answer = proxy()
    emit("service", success=answer.success, message=answer.message)

    ticks: List[float] = []
    done = threading.Event()

    def tick(event: Any) -> None:
        ticks.append(event.current_real.to_sec())
        if len(ticks) >= 3:
            done.set()

    timer = rospy.Timer(rospy.Duration(0.05), tick)
    done.wait(20)
    timer.shutdown()
    emit("timer", ticks=len(ticks))

    t = rospy.get_time()
    emit("time", get_time=t, rostime=rospy.get_rostime().to_sec(), wall=time.time())
    rospy.loginfo("plain_probe says hello on /rosout")

    msg = rospy.wait_for_message(topic, String, timeout=30)
    header = getattr(msg, "_connection_header", None) or {}
    emit("wait_for_message", data=msg.data, transport=header.get("transport", "TCPROS"))
    try:
        rospy.wait_for_message("/nobody_publishes_this", String, timeout=0.3)
        emit("wait_timeout", raised=False)
    except rospy.ROSException as exc:
        emit("wait_timeout", raised=True, text=str(exc))

    rospy.signal_shutdown("plain_probe done")
    emit("shutdown", is_shutdown=rospy.is_shutdown(), hooks=shutdown_hooks)


def mode_announce(args: List[str]) -> None:
    from std_msgs.msg import String

    topic = args[args.index("--topic") + 1] if "--topic" in args else "chatter"
    rospy.init_node("plain_probe")
    peers: List[str] = []

    class Welcome(rospy.SubscribeListener):  # type: ignore[misc]
        def peer_subscribe(self, topic_name: str, topic_publish: Any, peer_publish: Any) -> None:
            peers.append(topic_name)
            emit("peer_subscribe", topic=topic_name, n=len(peers))
            peer_publish(String(data="welcome %d" % len(peers)))

        def peer_unsubscribe(self, topic_name: str, num_peers: int) -> None:
            emit("peer_unsubscribe", topic=topic_name, num_peers=num_peers)

    pub = rospy.Publisher(topic, String, subscriber_listener=Welcome(), headers={"robot": "r2"}, queue_size=10,
                          tcp_nodelay=True)
    emit("ready", node=rospy.get_name(), topic=pub.resolved_name, uri=rospy.get_node_uri(), pid=os.getpid())
    rospy.spin()


def mode_latched(args: List[str]) -> None:
    from std_msgs.msg import String

    rospy.init_node("plain_probe")
    for topic in args[args.index("--topics") + 1].split(","):
        first = threading.Event()
        rospy.Subscriber(topic, String, lambda _msg: first.set())
        first.wait(30)
        # the topic is subscribed already: rospy hands the new subscriber the latched message at once
        msg = rospy.wait_for_message(topic, String, timeout=3)
        header = getattr(msg, "_connection_header", None) or {}
        emit("latched", topic=topic, data=msg.data, transport=header.get("transport", "TCPROS"))


def main() -> None:
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "argv":
        mode_argv(args)
    elif mode == "raise":
        raise RuntimeError("boom from the script")
    elif mode == "exit-message":
        sys.exit("bye from the script")
    elif mode == "latched":
        mode_latched(args)
    elif mode == "announce":
        mode_announce(args)
    elif mode == "services":
        mode_services(args)
    else:
        sys.exit("unknown mode %r" % mode)


if __name__ == "__main__":
    main()
