"""A whole robot on one host, under what users get (no profile, no ``MICROS_RT_*`` setting), then a ROS 2 node
that comes and goes; every message, call and goal accounted for in one table.

    .venv/bin/python tests/robot.py [--domain N] [--no-cyclonedds-uri] [--json]

``scripts/robot_demo.sh`` runs it (after ``scripts/setup.sh``); ``tests/integration/test_robot.py`` runs
:func:`run_robot` and asserts the table. It starts its own ``rosmaster`` on a free port and, on its DDS domain:

- unmodified rospy scripts under ``micros-rt run``: a talker (``/robot/chatter``, 25 Hz), a listener, a latched
  map (``/robot/map``) and a late listener of it, a ``rospy.Service`` server and client, an actionlib
  ``SimpleActionServer`` and ``SimpleActionClient`` (goal, feedback, result, cancel);
- micros_rt API nodes: a HIGH transport-priority ``/robot/cmd_vel`` publisher and its subscriber, and a node that
  offers the actionlib server's action to ROS 2 (``NodeHandle.offer_action_to_ros2``);
- stock ROS 1: a rospy listener (``/usr/bin/python3``), roscpp's ``topic_tools/relay`` (``/robot/chatter`` to
  ``/robot/chatter_cpp``, heard by another script under ``micros-rt run``) and ``rosbag record``;
- then, mid-stream, rclpy nodes join (their own venv and processes): one echoes ``/robot/chatter`` and the latched
  map, one calls the service, one sends an action goal; they leave, the robot goes on.

A row's "lost" counts messages missing after the first one that subscriber received (a subscriber that joined
mid-stream, as the rclpy echo and the roscpp relay's downstream do, starts at "first").
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

sys.path.insert(0, str(Path(__file__).resolve().parent))

import harness  # noqa: E402

MICROS_RT = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
PEERS = harness.PEERS_DIR
T = 45.0            # bound on any one wait (generous: a loaded machine)
COUNT = 200         # messages on /robot/chatter and /robot/cmd_vel, 25 Hz each (8 s)
ORDER = 20          # the actionlib goal's feedback messages


def robot_env(master: harness.RosMaster, domain: int, cyclonedds_uri: bool) -> Dict[str, str]:
    """The master's environment as a user's shell has it: no MICROS_RT_* setting, this robot's DDS domain, and
    Cyclone's configuration from CYCLONEDDS_URI (the loopback one of the tests) or none (micros_rt's own rule)."""
    env = {k: v for k, v in master.env.items() if not k.startswith("MICROS_RT_")}
    env.update(harness.dds_env(domain))
    if not cyclonedds_uri:
        env.pop("CYCLONEDDS_URI", None)
    return env


def _numbers(texts: List[str]) -> List[int]:
    return [int(m.group(1)) for t in texts if (m := re.search(r"(\d+)$", t or ""))]


def _row(link: str, kind: str, sent: int, got: List[int], transports: List[str], *, left: bool = False) -> Dict[str, Any]:
    """One table row: ``got`` the sequence numbers received, in order of arrival; ``left``: the subscriber left
    before the end (missing counts up to the last it received)."""
    first = got[0] if got else None
    end = (max(got) + 1 if got else 0) if left else sent
    expected = set(range(first, end)) if first is not None else set()
    return {"link": link, "kind": kind, "sent": sent, "received": len(got), "first": first,
            "lost": len(expected - set(got)), "duplicates": len(got) - len(set(got)),
            "in_order": got == sorted(got), "transports": sorted(set(transports))}


def _recv(peer: harness.Peer) -> List[Dict[str, Any]]:
    return [e for e in peer.events("recv")]


def run_robot(domain: int, *, cyclonedds_uri: bool = True, say: Callable[[str], None] = print) -> Dict[str, Any]:
    """Run the robot; return {"rows": [...], "calls": {...}, "goals": {...}, "seconds": float}."""
    t0 = time.monotonic()
    work = Path(tempfile.mkdtemp(prefix="micros_rt_robot_"))
    master = harness.RosMaster(workdir=work / "master")
    master.start()
    env = robot_env(master, domain, cyclonedds_uri)
    peers: List[harness.Peer] = []

    def start(name: str, argv: List[Any]) -> harness.Peer:
        peer = harness.Peer([str(a) for a in argv], env, name=name)
        peers.append(peer)
        return peer

    def run(script: str, *args: Any) -> List[str]:
        return [MICROS_RT, "run", str(PEERS / script), *[str(a) for a in args]]

    def ros2(script: str, *args: Any) -> List[str]:
        return [harness.ROS2_PYTHON, str(PEERS / script), *[str(a) for a in args]]

    bag = work / "robot.bag"
    try:
        say(f"robot: rosmaster at {master.uri}, DDS domain {domain}, CYCLONEDDS_URI "
            f"{'set' if cyclonedds_uri else 'unset'}; starting the robot's processes")
        # subscribers first: the talker waits for the four of /robot/chatter
        run_listener = start("run_listener", run("plain_listener.py", "--topic", "/robot/chatter",
                                                 "__name:=run_listener"))
        stock_listener = start("stock_listener", [harness.STOCK_PYTHON, str(PEERS / "plain_listener.py"), "--topic",
                                                  "/robot/chatter", "__name:=stock_listener"])
        start("roscpp_relay", ["/usr/lib/topic_tools/relay", "/robot/chatter", "/robot/chatter_cpp",
                               "__name:=roscpp_relay"])
        cpp_listener = start("run_cpp_listener", run("plain_listener.py", "--topic", "/robot/chatter_cpp",
                                                     "__name:=run_cpp_listener"))
        rosbag = start("rosbag_record", ["/usr/bin/rosbag", "record", "-O", str(bag), "/robot/chatter",
                                         "__name:=rosbag_record"])
        cmd_listener = start("mrt_cmd_listener", [harness.MICROS_RT_PYTHON, str(PEERS / "mrt_peer.py"), "listen",
                                                  "--topic", "/robot/cmd_vel", "--duration", 300,
                                                  "--node-name", "mrt_cmd_listener"])
        start("run_map", run("plain_talker.py", "--topic", "/robot/map", "--count", 1, "--latch", "--linger", 300,
                             "__name:=run_map"))
        service = start("run_service", run("plain_service.py", "serve", "/robot/set_mode", "--duration", 300,
                                           "__name:=run_service"))
        action_server = start("run_action_server", run("ros1_action_peer.py", "serve", "--name", "/robot/fib",
                                                       "--period", 0.01))
        for peer in (run_listener, stock_listener, cpp_listener, service, action_server):
            peer.wait_for("ready", T)
        cmd_listener.wait_for("ready", T)
        offer = start("mrt_action_offer", [harness.MICROS_RT_PYTHON, str(PEERS / "ros1_action_peer.py"), "bridge",
                                           "--to-ros2", "/robot/fib"])
        talker = start("run_talker", run("plain_talker.py", "--topic", "/robot/chatter", "--count", COUNT, "--rate", 25,
                                         "--wait-subscribers", 4, "--queue-size", 1000, "__name:=run_talker"))
        cmd_talker = start("mrt_cmd_talker", [harness.MICROS_RT_PYTHON, str(PEERS / "mrt_peer.py"), "talk", "--topic",
                                              "/robot/cmd_vel", "--count", COUNT, "--rate", 25, "--wait-subscribers", 1,
                                              "--qos", json.dumps({"transport_priority": "HIGH"}),
                                              "--node-name", "mrt_cmd_talker", "--linger", 2])
        talker.wait_for("ready", T)
        offer.wait_for("ready", T)
        late_map = start("run_map_listener", run("plain_listener.py", "--topic", "/robot/map", "--count", 1,
                                                 "--duration", T, "__name:=run_map_listener"))
        client = start("run_service_client", run("plain_service.py", "call", "/robot/set_mode", "--count", 20,
                                                 "__name:=run_service_client"))
        action_client = start("run_action_client", run("plain_action_client.py", "/robot/fib", "--order", ORDER,
                                                        "--wait", T, "__name:=run_action_client"))
        run_listener.wait_for_count("recv", 40, T)
        say("robot: ROS 1 side running; rclpy nodes join")

        # a ROS 2 node joins mid-stream: echoes a topic and the latched map, calls the service, sends a goal, leaves
        echo = start("rclpy_echo", ros2("ros2_peer.py", "listen", "--topic", "/robot/chatter", "--count", 20,
                                        "--duration", 60))
        map2 = start("rclpy_map", ros2("ros2_peer.py", "listen", "--topic", "/robot/map", "--count", 1,
                                       "--durability", "transient_local", "--duration", 60))
        calls2 = start("rclpy_service_client", ros2("ros2_service_peer.py", "call", "--plan", json.dumps([
            {"name": "/robot/set_mode", "type": "std_srvs/srv/SetBool", "args": {"data": True}, "count": 5,
             "timeout": 10, "wait": 30}])))
        goal2 = start("rclpy_action_client", ros2("ros2_action_peer.py", "call", "--plan", json.dumps([
            {"label": "fib", "name": "/robot/fib", "order": 10, "wait": 30}])))
        for peer in (echo, map2, calls2, goal2):
            peer.wait(90)
        say("robot: the rclpy nodes left; the robot goes on")

        talker.wait_for("done", T + COUNT / 25.0)
        cmd_talker.wait_for("done", T + COUNT / 25.0)
        late_map.wait(T)
        client.wait(T)
        action_client.wait(90)
        # the last messages reach every subscriber (the relay's downstream one hop later)
        harness.wait_until(lambda: len(_recv(run_listener)) >= COUNT and len(_recv(stock_listener)) >= COUNT
                           and len(_recv(cmd_listener)) >= COUNT, T, message="the last messages")
        harness.wait_until(lambda: _numbers([e["data"] for e in _recv(cpp_listener)])[-1:] == [COUNT - 1], T,
                           message="the last message through roscpp's relay")
        rosbag.stop()
        info = subprocess.run(["/usr/bin/rosbag", "info", "--yaml", "--key=messages", str(bag)], env=env,
                              capture_output=True, text=True, timeout=60)
        bagged = int(info.stdout.strip() or 0)

        sent = int(talker.wait_for("done", 1)["sent"])
        cmd_sent = int(cmd_talker.wait_for("done", 1)["statistics"].get("published", COUNT))
        rows = [
            _row("run_talker -> run_listener (micros-rt run)", "topic", sent,
                 _numbers([e["data"] for e in _recv(run_listener)]), [e["transport"] for e in _recv(run_listener)]),
            _row("run_talker -> stock rospy listener", "topic", sent,
                 _numbers([e["data"] for e in _recv(stock_listener)]), [e["transport"] for e in _recv(stock_listener)]),
            _row("run_talker -> rosbag record (roscpp)", "topic", sent, list(range(sent - bagged, sent)), ["TCPROS"]),
            _row("run_talker -> roscpp relay -> run_cpp_listener", "topic", sent,
                 _numbers([e["data"] for e in _recv(cpp_listener)]), [e["transport"] for e in _recv(cpp_listener)]),
            _row("run_talker -> rclpy echo (joined mid-stream)", "topic", sent,
                 [int(e["data"].split()[-1]) for e in echo.events("recv")], ["DDS"] if echo.events("recv") else [],
                 left=True),
            _row("mrt_cmd_talker (HIGH) -> mrt_cmd_listener", "topic", cmd_sent,
                 _numbers([e["data"] for e in _recv(cmd_listener)]), [e["transport"] for e in _recv(cmd_listener)]),
            _row("run_map (latched) -> late run listener", "latched", 1,
                 [0 for _ in _recv(late_map)], [e["transport"] for e in _recv(late_map)]),
            _row("run_map (latched) -> rclpy (transient_local)", "latched", 1,
                 [0 for _ in map2.events("recv")], ["DDS"] if map2.events("recv") else []),
        ]
        responses = client.events("response")
        summary = calls2.events("summary")
        results = {e["label"]: e for e in action_client.events("result")}
        results2 = {e["label"]: e for e in goal2.events("result")}
        calls = {
            "run client -> run server (rospy.Service)": {"sent": 20, "answered": len(responses),
                                                         "right": sum(1 for i, r in enumerate(responses)
                                                                      if r["success"] == (i % 2 == 0))},
            "rclpy client -> run server": {"sent": 5, "answered": summary[0]["ok"] if summary else 0,
                                           "right": summary[0]["ok"] if summary else 0},
        }
        goals = {
            "run actionlib client -> run server: goal": results.get("fib", {}),
            "run actionlib client -> run server: cancel": results.get("cancel", {}),
            "rclpy action client -> run server (offered by a micros_rt node)": results2.get("fib", {}),
        }
        report = {"rows": rows, "calls": calls, "goals": goals, "seconds": time.monotonic() - t0}
        if any(c["answered"] < c["sent"] for c in calls.values()):   # what the server and its ROS 2 helper said
            server_log, client_log = service.stderr_tail(60), calls2.stderr_tail(20) + "\n" + json.dumps(summary)
            report.update(server_log=server_log, rclpy_client_log=client_log)
            say(f"run server's stderr:\n{server_log}\nrclpy client:\n{client_log}")
        say(format_table(report))
        return report
    finally:
        stopping = [threading.Thread(target=peer.stop) for peer in peers]  # SIGINT to all at once, as roslaunch
        for t in stopping:
            t.start()
        for t in stopping:
            t.join()
        master.cleanup()
        subprocess.run(["rm", "-rf", str(work)], check=False)


def format_table(report: Dict[str, Any]) -> str:
    lines = [f"{'link':52} {'kind':8} {'sent':>5} {'recv':>5} {'first':>5} {'lost':>4}  transport"]
    for r in report["rows"]:
        lines.append(f"{r['link']:52} {r['kind']:8} {r['sent']:5} {r['received']:5} "
                     f"{'-' if r['first'] is None else r['first']:>5} {r['lost']:4}  {','.join(r['transports'])}")
    for name, c in report["calls"].items():
        lines.append(f"{name:52} {'service':8} {c['sent']:5} {c['answered']:5} {'':>5} {c['sent'] - c['answered']:4}  "
                     f"answers right: {c['right']}")
    for name, g in report["goals"].items():
        lines.append(f"{name:52} {'action':8} {'':5} {'':5} {'':>5} {'':4}  {g.get('status_name', 'NONE')}, "
                     f"feedback {g.get('feedback', 0)}{' in order' if g.get('feedback_in_order') else ''}")
    lines.append(f"robot: {report['seconds']:.0f} s")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--domain", type=int, default=230, help="the robot's DDS domain (ROS_DOMAIN_ID)")
    ap.add_argument("--no-cyclonedds-uri", action="store_true",
                    help="leave CYCLONEDDS_URI unset (micros_rt's own loopback rule), as a user without ROS 2 has it")
    ap.add_argument("--json", action="store_true", help="print the report as one JSON line at the end")
    args = ap.parse_args()
    report = run_robot(args.domain, cyclonedds_uri=not args.no_cyclonedds_uri)
    if args.json:
        print(json.dumps(report))
    bad = [r for r in report["rows"] if r["lost"] or not r["received"]]
    bad += [c for c in report["calls"].values() if c["answered"] < c["sent"]]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
