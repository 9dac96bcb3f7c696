"""CPU per message of the MQTT bridge (issue 37, deliverable 5): ``micros-rt mqtt-bridge`` and, when given, the
real C++ mqtt_client (ROS 1) with the same parameter file, one at a time, on loopback.

    .venv/bin/python benchmarks/mqtt_cpu.py                                   # micros_rt's bridge, all cases
    .venv/bin/python benchmarks/mqtt_cpu.py --real-client /path/to/mqtt_client_node --rounds 3
    .venv/bin/python benchmarks/mqtt_cpu.py --cases string_out --profile /tmp/prof   # py-spy, if installed
    .venv/bin/python benchmarks/mqtt_cpu.py --old-root /tmp/main_checkout ...   # also another checkout's bridge

The real client: ``benchmarks/build_mqtt_client.sh`` builds it from mqtt_client's sources.

Cases: ``string_out`` (std_msgs/String, 100 Hz, ROS -> MQTT), ``string_in`` (MQTT -> ROS), ``image_out`` and
``image_in`` (sensor_msgs/Image 640x480 rgb8, 921,600 data bytes, 10 Hz). ROS side: a stock rospy publisher or
subscriber (TCPROS, /usr/bin/python3); MQTT side: a paho client in this process that publishes (the 2.x type
announcement, retained, then the payloads) or counts. Each case gets its own rosmaster and mosquitto; the bridge
runs ``--warmup`` seconds, then its process's CPU time (utime + stime of /proc/<pid>/stat) is read over
``--duration`` seconds and divided by the messages that crossed it in that window. Nothing is built here: the real
client is a binary you give (``--real-client``), started with its private parameters loaded by ``rosparam``.
ROS -> MQTT cases give the bridge ``mqtt_client_version: 2`` (mqtt_client ignores the key): no peer announces on
the benchmark's broker, so by default the bridge would hold a topic's first 10 s (issue 44) and the window would
measure that instead of the steady state. ``idle_busy_peer``: with ``--real-client`` the busy peer is a second
real client (node ``/busy_peer``) fed by a stock rospy publisher at 1,000 msg/s, else a paho client in this
process. ``--old-root``: a third stack, ``micros_rt_old``, the bridge of another checkout (its ``micros_rt``
imported from there, this venv), alternating with the others in each round (A/B in one run).
Results: a table on stdout and ``--out`` (JSON).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
STOCK_PYTHON = "/usr/bin/python3"
MRT_PYTHON = sys.executable          # the project's venv, which runs this script
MOSQUITTO = "/usr/sbin/mosquitto"
ROSMASTER = "/usr/bin/rosmaster"
ROSPARAM = "/usr/bin/rosparam"
CLK_TCK = os.sysconf("SC_CLK_TCK")

CASES: Dict[str, Dict[str, Any]] = {
    "string_out": {"type": "std_msgs/String", "rate": 100.0, "direction": "out"},
    "string_in": {"type": "std_msgs/String", "rate": 100.0, "direction": "in"},
    "image_out": {"type": "sensor_msgs/Image", "rate": 10.0, "direction": "out"},
    "image_in": {"type": "sensor_msgs/Image", "rate": 10.0, "direction": "in"},
    "string_out_1k": {"type": "std_msgs/String", "rate": 1000.0, "direction": "out"},
    "string_in_1k": {"type": "std_msgs/String", "rate": 1000.0, "direction": "in"},
    # the bridge has nothing to bridge (a ROS topic nobody publishes, an MQTT topic nobody writes) while an
    # mqtt_client peer streams String at 1,000 msg/s, with its type announcement before each, on another topic
    "idle_busy_peer": {"type": "std_msgs/String", "rate": 1000.0, "direction": "idle"},
}

#: The stock rospy publisher (ROS -> MQTT cases): the message is built once, sent at the rate until killed.
PUBLISHER = r"""
import sys, time, rospy, roslib.message
kind, rate = sys.argv[1], float(sys.argv[2])
rospy.init_node("bench_pub", anonymous=True, disable_signals=True)
cls = roslib.message.get_message_class(kind)
msg = cls()
if kind == "sensor_msgs/Image":
    msg.height, msg.width, msg.encoding, msg.step = 480, 640, "rgb8", 640 * 3
    msg.data = bytes(range(256)) * 3600
else:
    msg.data = "micros_rt bench " + "x" * 40
pub = rospy.Publisher("/bench/ros_in", cls, queue_size=10)
while pub.get_num_connections() == 0:
    time.sleep(0.05)
print("ready", flush=True)
period, t = 1.0 / rate, time.monotonic()
while True:
    t += period
    time.sleep(max(0.0, t - time.monotonic()))
    pub.publish(msg)
"""

#: The stock rospy subscriber (MQTT -> ROS cases): prints its count when asked (a line on stdin).
SUBSCRIBER = r"""
import sys, threading, rospy, roslib.message
kind = sys.argv[1]
rospy.init_node("bench_sub", anonymous=True, disable_signals=True)
count = [0]
def cb(msg):
    count[0] += 1
rospy.Subscriber("/bench/ros_out", rospy.AnyMsg, cb, queue_size=100)
print("ready", flush=True)
for line in sys.stdin:
    print(count[0], flush=True)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def wait_port(port: int, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"nothing listens on {port} after {timeout} s")


def stop(proc: Optional["subprocess.Popen[Any]"]) -> Optional[int]:
    """SIGINT, then SIGKILL after 3 s (rosmaster often needs more than SIGINT); the exit code (None: no process).
    Also used by the other benchmarks of this folder (mqtt_start_order.py, mcu_cvra_live.py)."""
    if proc is None:
        return None
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(3)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
    return proc.returncode


def image_payload() -> bytes:
    from sensor_msgs.msg import Image

    msg = Image(height=480, width=640, encoding="rgb8", step=640 * 3, data=bytes(range(256)) * 3600)
    return serialized(msg)


def serialized(msg: Any) -> bytes:
    import io

    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


def run_case(name: str, stack: str, args: argparse.Namespace, work: Path) -> Dict[str, Any]:
    import paho.mqtt.client as paho
    import roslib.message
    from paho.mqtt.enums import CallbackAPIVersion

    sys.path.insert(0, str(ROOT))
    from micros_rt.transports.mqtt import codec

    case = CASES[name]
    mport, bport = free_port(), free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_") and k != "PYTHONPATH"}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{mport}", ROS_IP="127.0.0.1", PYTHONUNBUFFERED="1")
    conf = work / f"mosquitto_{name}_{stack}.conf"
    conf.write_text(f"listener {bport} 127.0.0.1\nallow_anonymous true\n" + ("user root\n" if os.geteuid() == 0
                                                                                else ""))
    procs: List["subprocess.Popen[Any]"] = []
    result: Dict[str, Any] = {"case": name, "stack": stack, "type": case["type"], "rate": case["rate"]}
    client: Optional[Any] = None
    try:
        procs.append(subprocess.Popen([ROSMASTER, "--core", "-p", str(mport)], env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        wait_port(mport)
        wait_port(bport)
        entry = ({"ros2mqtt": [{"ros_topic": "/bench/ros_in", "mqtt_topic": "bench/mqtt_out"}]}
                 if case["direction"] == "out" else
                 {"mqtt2ros": [{"mqtt_topic": "bench/mqtt_in", "ros_topic": "/bench/ros_out"}]}
                 if case["direction"] == "in" else
                 {"ros2mqtt": [{"ros_topic": "/bench/nobody", "mqtt_topic": "bench/quiet_out"}],
                  "mqtt2ros": [{"mqtt_topic": "bench/quiet_in", "ros_topic": "/bench/quiet_in"}]})
        params = work / f"params_{name}_{stack}.yaml"
        import yaml

        if case["direction"] == "out":   # the steady state, not the first 10 s's hold (see the docstring)
            entry["mqtt_client_version"] = 2
        params.write_text(yaml.safe_dump({"broker": {"host": "127.0.0.1", "port": bport}, "bridge": entry}))
        if stack.startswith("micros_rt"):
            root = args.old_root if stack == "micros_rt_old" else str(ROOT)
            bridge = subprocess.Popen([MRT_PYTHON, "-m", "micros_rt.bridges.mqtt", "--params", str(params)], env=env,
                                      stdout=subprocess.DEVNULL,
                                      stderr=open(work / f"bridge_{name}_{stack}.log", "w"), cwd=root)
        else:
            subprocess.run([ROSPARAM, "load", str(params), "/mqtt_client"], env=env, check=True, timeout=30)
            bridge = subprocess.Popen([args.real_client], env=env, stdout=subprocess.DEVNULL,
                                      stderr=open(work / f"real_{name}.log", "w"))
        procs.append(bridge)

        received = [0]
        cls = roslib.message.get_message_class(case["type"])
        client = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv311)
        client.on_message = lambda c, u, m: received.__setitem__(0, received[0] + 1)
        client.connect("127.0.0.1", bport)
        client.loop_start()
        if case["direction"] == "out":
            client.subscribe("bench/mqtt_out", 0)
            pub = subprocess.Popen([STOCK_PYTHON, "-c", PUBLISHER, case["type"], str(case["rate"])], env=env,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            procs.append(pub)
            assert pub.stdout is not None and pub.stdout.readline().strip() == "ready"

            def count() -> int:
                return received[0]
        else:
            idle = case["direction"] == "idle"
            data_topic = "bench/busy" if idle else "bench/mqtt_in"
            sub = subprocess.Popen([STOCK_PYTHON, "-c", SUBSCRIBER, case["type"]], env=env, stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            procs.append(sub)
            assert sub.stdout is not None and sub.stdin is not None
            assert sub.stdout.readline().strip() == "ready"
            if idle:
                client.subscribe(data_topic, 0)
            real_peer = idle and bool(args.real_client)
            if real_peer:   # a real mqtt_client streams String at 1,000 msg/s from a stock rospy publisher
                peer_params = work / f"busy_peer_{name}_{stack}.yaml"
                peer_params.write_text(yaml.safe_dump({"broker": {"host": "127.0.0.1", "port": bport}, "bridge": {
                    "ros2mqtt": [{"ros_topic": "/bench/ros_in", "mqtt_topic": data_topic}]}}))
                subprocess.run([ROSPARAM, "load", str(peer_params), "/busy_peer"], env=env, check=True, timeout=30)
                procs.append(subprocess.Popen([args.real_client, "__name:=busy_peer"], env=env,
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
                pub = subprocess.Popen([STOCK_PYTHON, "-c", PUBLISHER, case["type"], str(case["rate"])], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
                procs.append(pub)
                assert pub.stdout is not None and pub.stdout.readline().strip() == "ready"
            msg = cls()
            if case["type"] == "sensor_msgs/Image":
                payload = image_payload()
            else:
                msg.data = "micros_rt bench " + "x" * 40
                payload = serialized(msg)
            announcement = codec.encode_msg_type(codec.RosMsgType.of(cls, stamped=False))
            if not real_peer:
                client.publish("mqtt_client/ros_msg_type/" + data_topic, announcement, 1, True)
            stop_pub = threading.Event()

            def publish_loop() -> None:   # mqtt_client's own sender: the announcement before every payload
                period, t = 1.0 / case["rate"], time.monotonic()
                while not stop_pub.is_set():
                    t += period
                    time.sleep(max(0.0, t - time.monotonic()))
                    if args.announce_each:
                        client.publish("mqtt_client/ros_msg_type/" + data_topic, announcement, 0, True)
                    client.publish(data_topic, payload, 0, False)

            if not real_peer:
                threading.Thread(target=publish_loop, daemon=True).start()
            result["_stop"] = stop_pub

            def count() -> int:
                if idle:                  # the peer's messages, as this process received them
                    return received[0]
                assert sub.stdin is not None and sub.stdout is not None
                sub.stdin.write("?\n")
                sub.stdin.flush()
                return int(sub.stdout.readline())

        time.sleep(args.warmup)
        n0, c0, t0 = count(), cpu_seconds(bridge.pid), time.monotonic()
        profiler = None
        if args.profile and stack.startswith("micros_rt"):
            Path(args.profile).mkdir(parents=True, exist_ok=True)
            py_spy = str(Path(sys.executable).parent / "py-spy")
            profiler = subprocess.Popen([py_spy, "record", "--pid", str(bridge.pid), "--duration",
                                         str(int(args.duration)), "--format", "raw", "--threads", "--gil",
                                         "--rate", "1000",
                                         "--output", str(Path(args.profile) / f"{name}.txt"), "--nonblocking"],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(args.duration)
        n1, c1, t1 = count(), cpu_seconds(bridge.pid), time.monotonic()
        if profiler is not None:
            profiler.wait(60)
        if "_stop" in result:
            result.pop("_stop").set()
        messages = n1 - n0
        cpu = c1 - c0
        result.update(window_s=round(t1 - t0, 2), messages=messages, expected=round(case["rate"] * (t1 - t0)),
                      cpu_s=round(cpu, 3), cpu_percent=round(100.0 * cpu / (t1 - t0), 2),
                      us_per_message=round(1e6 * cpu / messages, 1) if messages else None,
                      alive=bridge.poll() is None)
        return result
    finally:
        if client is not None:
            client.loop_stop()
            client.disconnect()
        for p in reversed(procs):
            stop(p)


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--real-client", default="", help="the real mqtt_client (ROS 1) binary to run beside micros_rt")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--warmup", type=float, default=4.0)
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--announce-each", action="store_true", default=True,
                    help="MQTT -> ROS: send the type announcement before every payload, as mqtt_client does")
    ap.add_argument("--no-announce-each", dest="announce_each", action="store_false")
    ap.add_argument("--profile", default="", help="py-spy record the micros_rt bridge into this directory")
    ap.add_argument("--old-root", default="", help="also run the bridge of this checkout (stack micros_rt_old)")
    ap.add_argument("--out", default=str(HERE / "results" / "mqtt_cpu.json"))
    args = ap.parse_args(argv)
    stacks = (["micros_rt"] + (["micros_rt_old"] if args.old_root else [])
              + (["mqtt_client"] if args.real_client else []))
    rows: List[Dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="mqtt_cpu_") as tmp:
        for r in range(args.rounds):
            for name in args.cases.split(","):
                for stack in (stacks if r % 2 == 0 else stacks[::-1]):
                    row = run_case(name, stack, args, Path(tmp))
                    row["round"] = r
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    summary: Dict[str, Dict[str, Any]] = {}
    for name in args.cases.split(","):
        for stack in stacks:
            mine = [x for x in rows if x["case"] == name and x["stack"] == stack and x["us_per_message"]]
            if mine:
                summary[f"{name}/{stack}"] = {
                    "cpu_percent": [x["cpu_percent"] for x in mine],
                    "us_per_message_median": statistics.median(x["us_per_message"] for x in mine),
                    "delivered": [f"{x['messages']}/{x['expected']}" for x in mine]}
    print("\n| case | stack | CPU % of a core (each round) | CPU per message (median) | delivered/expected |")
    print("| --- | --- | --- | --- | --- |")
    for key, s in summary.items():
        name, stack = key.split("/")
        print(f"| {name} | {stack} | {', '.join(f'{v:.2f}' for v in s['cpu_percent'])} | "
              f"{s['us_per_message_median']:.0f} us | {', '.join(s['delivered'])} |")
    if args.real_client:
        print()
        for name in args.cases.split(","):
            a, b = summary.get(f"{name}/micros_rt"), summary.get(f"{name}/mqtt_client")
            if a and b:
                ratio = a["us_per_message_median"] / b["us_per_message_median"]
                print(f"{name}: micros_rt / mqtt_client = {ratio:.2f}x")
                old = summary.get(f"{name}/micros_rt_old")
                if old:
                    print(f"{name}: micros_rt_old / mqtt_client = "
                          f"{old['us_per_message_median'] / b['us_per_message_median']:.2f}x")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                          "host_cpus": os.cpu_count(), "real_client": args.real_client or None,
                                          "old_root": args.old_root or None,
                                          "load_average": os.getloadavg(),
                                          "rows": rows, "summary": summary}, indent=1) + "\n")
    print(f"\nwritten: {args.out}")
    return 0


if __name__ == "__main__":
    if shutil.which(MOSQUITTO) is None and not Path(MOSQUITTO).exists():
        sys.exit("mosquitto is not installed")
    sys.exit(main(sys.argv[1:]))
