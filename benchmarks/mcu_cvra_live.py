"""CVRA's own ``cvra_rpc`` of three eras playing the board, live, against ``micros-rt mcu-bridge`` with no
``wire_form`` (issue 44): how many cases work per era.

    git clone --bare https://github.com/cvra/robot-software /tmp/cvra.git     # or any clone with its history
    .venv/bin/python benchmarks/mcu_cvra_live.py /tmp/cvra.git

CVRA's modules of each era are read from the commits ``scripts/capture_cvra_fixtures.py`` names (``git show``)
and imported in this process with its msgpack wrapper (CVRA's 2015 code used msgpack 0.4's ``encoding=``); nothing
of CVRA's is copied into this repository. Per era, with its own rosmaster, one bridge (loopback, the board too:
CVRA's clients do not bind) and one stock rospy node (``/usr/bin/python3``, no micros_rt) on the ROS side:

- the board streams ``odometry_raw`` (Pose2D) with the era's ``message.send`` (mid2015, final; the README era has
  no ``message`` module): one datagram every 0.2 s until the ROS listener has one, then 10 counted and serves ``cmd_vel`` datagrams with ``message.create_request_handler``;
- the board serves ``reset`` (std_srvs/Trigger), ``enable`` (SetBool), ``set_logger_level``
  (roscpp/SetLoggerLevel), ``ping`` (Trigger, its handler returns ``[True, "pong"]``) with
  ``service_call.create_request_handler`` on a ``socketserver`` TCP server, called from ROS (rospy
  ServiceProxy) through the bridge; each handler records what it was given;
- the board calls ``set_mode`` (SetBool, a stock rospy service) and ``clear`` (std_srvs/Empty, the documented
  empty-response case: the bridge answers nil, which CVRA's ``call()`` returns as None) with ``service_call.call``.

A case passes when both ends saw what the other meant: the handler got the era's own arguments (what that era's
client would have sent), the ROS caller got the handler's answer, the Pose2D and Twist fields are equal.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import socketserver
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "scripts"))
import capture_cvra_fixtures as cvra  # noqa: E402

sys.path.insert(0, str(HERE))
from mqtt_cpu import stop, wait_port  # noqa: E402

STOCK_PYTHON = "/usr/bin/python3"
# CVRA's message.send and service_call.call use unbound sockets: their datagrams and connections come from
# 127.0.0.1, and the bridge takes only the board's address
BOARD, BRIDGE = "127.0.0.1", "127.0.0.1"

#: the stock ROS side: calls the board's services, publishes cmd_vel, counts odometry, serves set_mode and clear
ROS_SIDE = r"""
import json, sys, time, rospy
from geometry_msgs.msg import Pose2D, Twist, Vector3
from std_srvs.srv import Trigger, SetBool, SetBoolResponse, Empty, EmptyResponse
from roscpp.srv import SetLoggerLevel
rospy.init_node("cvra_ros_side", disable_signals=True)
ns = sys.argv[1]
poses, served = [], []
rospy.Subscriber(ns + "/odometry", Pose2D, lambda m: poses.append([m.x, m.y, m.theta]))
rospy.Service(ns + "/set_mode", SetBool, lambda r: (served.append(["set_mode", r.data]),
              SetBoolResponse(success=True, message="mode on" if r.data else "mode off"))[1])
rospy.Service(ns + "/clear", Empty, lambda r: (served.append(["clear"]), EmptyResponse())[1])
cmd = rospy.Publisher(ns + "/cmd_vel", Twist, queue_size=10)
print("ready", flush=True)
for line in sys.stdin:
    what = line.strip()
    out = {}
    if what == "calls":
        for name, cls, args in (("reset", Trigger, ()), ("enable", SetBool, (True,)),
                                ("set_logger_level", SetLoggerLevel, ("rosout", "warn")), ("ping", Trigger, ())):
            try:
                rospy.wait_for_service(ns + "/" + name, 20)
                r = rospy.ServiceProxy(ns + "/" + name, cls)(*args)
                out[name] = {"ok": True, "answer": {k: getattr(r, k) for k in r.__slots__}}
            except Exception as e:
                out[name] = {"ok": False, "error": "%s: %s" % (type(e).__name__, e)}
    elif what == "cmd_vel":
        deadline = time.monotonic() + 20
        while cmd.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        for _ in range(3):
            cmd.publish(Twist(linear=Vector3(x=0.25), angular=Vector3(z=-0.5)))
            time.sleep(0.1)
        out = {"published": 3}
    elif what == "report":
        out = {"poses": poses, "served": served}
    print(json.dumps(out), flush=True)
"""

#: what each era's handler is given for the ROS calls, as that era's own client sends them
EXPECTED_ARGS: Dict[str, Dict[str, Any]] = {
    "final": {"reset": None, "enable": True, "set_logger_level": ["rosout", "warn"], "ping": None},
    "mid2015": {"reset": [], "enable": [True], "set_logger_level": ["rosout", "warn"], "ping": []},
    "readme": {"reset": {}, "enable": {"data": True}, "set_logger_level": {"logger": "rosout", "level": "warn"},
               "ping": {}},
}
#: what the era's own client sends for set_mode(True) and clear() (CVRA's call() arguments)
CALL_ARGS: Dict[str, Dict[str, Any]] = {
    "final": {"set_mode": True, "clear": None},
    "mid2015": {"set_mode": [True], "clear": []},
    "readme": {"set_mode": {"data": True}, "clear": {}},
}


def free_port(address: str, kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind((address, 0))
        return int(s.getsockname()[1])


def plain(value: Any) -> Any:
    """Tuples as lists, bytes as text: what the handler got, comparable with JSON."""
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {plain(k): plain(v) for k, v in value.items()}
    if isinstance(value, bytes):
        return value.decode("ascii", "replace")
    return value


def run_era(era: str, repo: Path, work: Path, bridge_root: str) -> Dict[str, Any]:
    mods = cvra.load_era(repo, era, work)
    sc, message = mods["service_call"], mods.get("message")
    ports = {"board_topic": free_port(BOARD, socket.SOCK_DGRAM), "board_service": free_port(BOARD, socket.SOCK_STREAM),
             "bridge_topic": free_port(BRIDGE, socket.SOCK_DGRAM),
             "bridge_service": free_port(BRIDGE, socket.SOCK_STREAM)}
    ns = f"/cv_{era}"
    config = work / f"{era}.yaml"
    config.write_text(
        f"microcontroller: {{address: {BOARD}, topic_port: {ports['board_topic']}, "
        f"service_port: {ports['board_service']}}}\n"
        f"bind: {{address: {BRIDGE}, topic_port: {ports['bridge_topic']}, service_port: {ports['bridge_service']}}}\n"
        "stats_period: 0.3\n"
        + (f"from_microcontroller:\n  - {{topic: {ns}/odometry, type: geometry_msgs/Pose2D, name: odometry_raw}}\n"
           f"to_microcontroller:\n  - {{topic: {ns}/cmd_vel, type: geometry_msgs/Twist, name: cmd_vel}}\n"
           if message is not None else "")
        + "services_on_microcontroller:\n"
        + "".join(f"  - {{service: {ns}/{n}, type: {t}, name: {n}}}\n" for n, t in (
            ("reset", "std_srvs/Trigger"), ("enable", "std_srvs/SetBool"),
            ("set_logger_level", "roscpp/SetLoggerLevel"), ("ping", "std_srvs/Trigger")))
        + "services_for_microcontroller:\n"
        + f"  - {{service: {ns}/set_mode, type: std_srvs/SetBool, name: set_mode}}\n"
        + f"  - {{service: {ns}/clear, type: std_srvs/Empty, name: clear}}\n")
    mport = free_port("127.0.0.1", socket.SOCK_STREAM)
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_") and k != "PYTHONPATH"}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{mport}", ROS_IP="127.0.0.1", PYTHONUNBUFFERED="1")
    procs: List["subprocess.Popen[Any]"] = []
    servers: List[Any] = []
    handled: Dict[str, Any] = {}
    cmd_vel: List[Any] = []
    cases: List[Dict[str, Any]] = []

    def case(name: str, ok: bool, detail: Any) -> None:
        cases.append({"case": name, "ok": bool(ok), "detail": detail})

    try:
        procs.append(subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(mport)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        wait_port(mport)
        ros = subprocess.Popen([STOCK_PYTHON, "-c", ROS_SIDE, ns], env=env, stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=open(work / f"ros_{era}.log", "w"), text=True)
        procs.append(ros)
        assert ros.stdout is not None and ros.stdin is not None
        assert ros.stdout.readline().strip() == "ready"

        def ask(what: str) -> Any:
            assert ros.stdin is not None and ros.stdout is not None
            ros.stdin.write(what + "\n")
            ros.stdin.flush()
            return json.loads(ros.stdout.readline())

        bridge = subprocess.Popen([sys.executable, "-m", "micros_rt.bridges.mcu", "--config", str(config), "--name",
                                   f"mcu_bridge_{era}", "--json"], env=env, stdout=subprocess.PIPE,
                                  stderr=open(work / f"bridge_{era}.log", "w"), text=True, cwd=bridge_root)
        procs.append(bridge)
        assert bridge.stdout is not None
        for line in bridge.stdout:
            if '"ready"' in line:
                break
        stats: List[Dict[str, Any]] = []
        threading.Thread(target=lambda: [stats.append(json.loads(ln)) for ln in bridge.stdout  # type: ignore
                                         if ln.startswith("{")], daemon=True).start()

        def handler(name: str, answer: Any) -> Any:
            def handle(params: Any) -> Any:
                handled[name] = plain(params)
                return answer
            return handle

        handlers = {"reset": handler("reset", True), "enable": handler("enable", True),
                    "set_logger_level": handler("set_logger_level", True),
                    "ping": handler("ping", [True, "pong"])}
        tcp = socketserver.ThreadingTCPServer((BOARD, ports["board_service"]), sc.create_request_handler(handlers))
        tcp.daemon_threads = True
        servers.append(tcp)
        threading.Thread(target=tcp.serve_forever, daemon=True).start()
        bridge_topic = (BRIDGE, ports["bridge_topic"])
        bridge_service = (BRIDGE, ports["bridge_service"])
        if message is not None:
            udp = socketserver.UDPServer((BOARD, ports["board_topic"]), message.create_request_handler(
                {"cmd_vel": lambda args: cmd_vel.append(plain(args))}))
            servers.append(udp)
            threading.Thread(target=udp.serve_forever, daemon=True).start()
            # the board speaks first: its stream names its era. Until the ROS listener's link to the bridge is up,
            # what the bridge publishes reaches nobody: one datagram a 0.2 s until the listener has one, then 10
            deadline = time.monotonic() + 20
            while not ask("report")["poses"] and time.monotonic() < deadline:
                message.send(bridge_topic, "odometry_raw", [1.5, 2.5, 0.5])
                time.sleep(0.2)
            time.sleep(0.5)
            warmup = len(ask("report")["poses"])
            for _ in range(10):
                message.send(bridge_topic, "odometry_raw", [1.5, 2.5, 0.5])
                time.sleep(0.05)
        # the board calls ROS with its era's client
        results: Dict[str, Any] = {}
        for name in ("set_mode", "clear"):
            try:
                results[name] = {"ok": True, "answer": plain(sc.call(bridge_service, name, CALL_ARGS[era][name]))}
            except Exception as exc:  # CVRA's call() raises what it cannot read
                results[name] = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        calls = ask("calls")
        if message is not None:
            ask("cmd_vel")
            deadline = time.monotonic() + 10
            while len(cmd_vel) < 3 and time.monotonic() < deadline:
                time.sleep(0.05)
        time.sleep(0.5)
        report = ask("report")
        # the cases
        if message is not None:
            poses = report["poses"][warmup:]
            case("odometry_raw -> Pose2D", len(poses) == 10 and all(abs(p[0] - 1.5) < 1e-6 and abs(p[1] - 2.5) < 1e-6
                                                                    and abs(p[2] - 0.5) < 1e-6 for p in poses),
                 f"{len(poses)} of 10, {poses[:1]}")
            want = [[0.25, 0.0, 0.0], [0.0, 0.0, -0.5]]
            got = cmd_vel[0] if cmd_vel else None
            # final: args is the list of fields; mid2015: the array's tail is the list of fields
            case("Twist -> cmd_vel", len(cmd_vel) == 3 and got == want, f"{len(cmd_vel)} of 3, args {got}")
        mode = results["set_mode"]
        # final's call() returns the one object it reads; mid2015's and readme's a tuple of every object
        expected_answer = [True, "mode on"] if era == "final" else [[True, "mode on"]]
        case("board calls set_mode", mode.get("answer") == expected_answer
             and ["set_mode", True] in report["served"], mode)
        clear = results["clear"]
        expected_clear = None if era == "final" else [None]
        case("board calls clear (empty response: CVRA's call() returns None, documented)",
             clear.get("ok") and clear.get("answer") == expected_clear and ["clear"] in report["served"], clear)
        for name in ("reset", "enable", "set_logger_level", "ping"):
            c = calls[name]
            args_ok = name in handled and handled[name] == EXPECTED_ARGS[era][name]
            answer_ok = c["ok"] and (name == "set_logger_level" or c["answer"].get("success") is True)
            if name == "ping":
                answer_ok = answer_ok and c["answer"].get("message") == "pong"
            case(f"ROS calls {name}", args_ok and answer_ok, {"handler_got": handled.get(name, "(not called)"),
                                                              "ros_caller": c})
        link = stats[-1].get("link") if stats else None
        return {"era": era, "commit": cvra.ERAS[era][0], "passed": sum(c["ok"] for c in cases), "cases": len(cases),
                "link": link, "detail": cases}
    finally:
        for s in servers:
            s.shutdown()
            s.server_close()
        for p in reversed(procs):
            stop(p)


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("repo", type=Path, help="a clone of cvra/robot-software with its history (bare or not)")
    ap.add_argument("--eras", default="final,mid2015,readme")
    ap.add_argument("--bridge-root", default=str(ROOT), help="run the bridge of this checkout (e.g. an older one)")
    ap.add_argument("--out", default=str(HERE / "results" / "mcu_cvra_live.json"))
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="mcu_cvra_live_") as tmp:
        for era in args.eras.split(","):
            row = run_era(era, args.repo, Path(tmp), args.bridge_root)
            rows.append(row)
            print(json.dumps(row, default=str), flush=True)
    print("\n| era (commit) | cases passed, no wire_form | the bridge learnt |")
    print("| --- | --- | --- |")
    for r in rows:
        print(f"| {r['era']} ({r['commit'][:8]}) | {r['passed']} of {r['cases']} | {r['link']} |")
        for c in r["detail"]:
            if not c["ok"]:
                print(f"|   failed: {c['case']} | {json.dumps(c['detail'], default=str)[:300]} | |")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                          "bridge_root": args.bridge_root, "rows": rows}, indent=1,
                                         default=str) + "\n")
    print(f"\nwritten: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
