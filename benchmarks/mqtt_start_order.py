"""Corrupted messages at a real mqtt_client 1.1.0 beside ``micros-rt mqtt-bridge`` with default settings, in each
start order (issue 44): the bridge first, the 1.1.0 first, both together, and a 1.1.0 that only reads.

    benchmarks/build_mqtt_client.sh /path/to/mqtt_client.git /tmp/mqttc          # builds 1.1.0 (and 2.3.0)
    .venv/bin/python benchmarks/mqtt_start_order.py --real-v1 /tmp/mqttc/1.1.0-f9b53da/mqtt_client

Each row gets its own rosmaster and mosquitto on loopback. A stock rospy node (``/usr/bin/python3``) publishes
``std_msgs/String`` texts ``so <n> <time>`` on ``/so/to_bridge`` at ``--rate`` Hz from the start; the bridge
carries them to MQTT ``so/data`` (``ros2mqtt``, no ``mqtt_client_version`` unless the row says so); the real 1.1.0
(node ``/mqtt_client``) carries ``so/data`` back to ROS ``/so/from_real`` (``mqtt2ros``) and, unless it only
reads, writes its own topic ``/so/to_real`` -> ``so/real_data``, which the stock node starts publishing 3 s after
the 1.1.0 started (the issue's "publishing 3 s after that"): that is its type announcement, in 1.x. The stock node
checks every text that arrives on ``/so/from_real`` against the texts it sent: one it did not send is
**corrupted** (1.1.0 read a 2.x payload: it takes the first byte for its "stamped" flag). "after" counts the texts
sent after both programs ran that never arrived (held messages arrive late, not lost). The table also gives
how many of the missing texts never reached the broker (a paho client on the bridge's MQTT topic reads both
generations' payloads), whether the 1.1.0 was still running at the end, and the bridge's counters (``held``, ``held_dropped`` when the
newest 1,000 overflowed) and warnings about generations.
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from mqtt_cpu import free_port, stop, wait_port  # noqa: E402
ROOT = HERE.parent
STOCK_PYTHON = "/usr/bin/python3"
MRT_PYTHON = sys.executable

#: the stock node: one talker to the bridge, one to the 1.1.0 (on "real_pub"), one listener of what 1.1.0 republishes
STOCK = r"""
import json, sys, threading, time, rospy
from std_msgs.msg import String
rate = float(sys.argv[1])
rospy.init_node("so_stock", disable_signals=True)
sent, real_sent, lock = {}, [0], threading.Lock()
both_at = [None]
got = {"good": 0, "corrupted": 0, "examples": [], "late_good": 0}
seen = set()
def cb(msg):
    with lock:
        if msg.data in sent:
            got["good"] += 1
            seen.add(msg.data)
        else:
            got["corrupted"] += 1
            if len(got["examples"]) < 3:
                got["examples"].append(msg.data)
rospy.Subscriber("/so/from_real", String, cb, queue_size=1000)
pub = rospy.Publisher("/so/to_bridge", String, queue_size=100)
real = rospy.Publisher("/so/to_real", String, queue_size=100)
go_real = threading.Event()
def talk():
    n, period, t = 0, 1.0 / rate, time.monotonic()
    while True:
        t += period
        time.sleep(max(0.0, t - time.monotonic()))
        text = "so %d %.6f" % (n, time.time())
        with lock:
            sent[text] = time.monotonic()
        pub.publish(String(data=text))
        if go_real.is_set():
            real.publish(String(data="real %d" % n))
        n += 1
threading.Thread(target=talk, daemon=True).start()
print("ready", flush=True)
for line in sys.stdin:
    cmd = line.strip()
    if cmd == "real_pub":
        go_real.set()
    elif cmd == "both":
        both_at[0] = time.monotonic()
    elif cmd == "report":
        with lock:
            after = [x for x, at in sent.items() if both_at[0] is not None and at >= both_at[0] + 1.0]
            missing = [x for x in after if x not in seen]
            print(json.dumps({"sent": len(sent), "received": got["good"] + got["corrupted"], "good": got["good"],
                              "corrupted": got["corrupted"], "examples": got["examples"],
                              "sent_after_both": len(after), "missing_after_both": len(missing),
                              "missing_texts": missing}), flush=True)
"""

ROWS = [
    # name, who starts first, seconds between, 1.1.0 publishes, bridge's mqtt_client_version
    ("bridge first, 1.1.0 4 s later", "bridge", 4.0, True, None),
    ("1.1.0 first, bridge 4 s later", "real", 4.0, True, None),
    ("together", "bridge", 0.0, True, None),
    ("1.1.0 only reads, bridge first", "bridge", 4.0, False, None),
    ("1.1.0 only reads, bridge given mqtt_client_version: 1", "bridge", 4.0, False, 1),
]


def run_row(row: Any, args: argparse.Namespace, work: Path, index: int) -> Dict[str, Any]:
    import yaml

    name, first, gap, real_publishes, version = row
    mport, bport = free_port(), free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_") and k != "PYTHONPATH"}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{mport}", ROS_IP="127.0.0.1", PYTHONUNBUFFERED="1")
    conf = work / f"mosquitto_{index}.conf"
    conf.write_text(f"listener {bport} 127.0.0.1\nallow_anonymous true\n" + ("user root\n" if os.geteuid() == 0
                                                                                else ""))
    broker = {"host": "127.0.0.1", "port": bport}
    bridge_entry: Dict[str, Any] = {"ros2mqtt": [{"ros_topic": "/so/to_bridge", "mqtt_topic": "so/data"}]}
    if version is not None:
        bridge_entry["mqtt_client_version"] = version
    bridge_params = work / f"bridge_{index}.yaml"
    bridge_params.write_text(yaml.safe_dump({"broker": broker, "bridge": bridge_entry}))
    real_entry: Dict[str, Any] = {"mqtt2ros": [{"mqtt_topic": "so/data", "ros_topic": "/so/from_real"}]}
    if real_publishes:
        real_entry["ros2mqtt"] = [{"ros_topic": "/so/to_real", "mqtt_topic": "so/real_data"}]
    real_params = work / f"real_{index}.yaml"
    real_params.write_text(yaml.safe_dump({"broker": broker, "bridge": real_entry}))
    procs: List["subprocess.Popen[Any]"] = []
    bridge_log = work / f"bridge_{index}.log"
    real_log = work / f"real_{index}.log"
    try:
        procs.append(subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(mport)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen(["/usr/sbin/mosquitto", "-c", str(conf)], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        wait_port(mport)
        wait_port(bport)
        subprocess.run(["/usr/bin/rosparam", "load", str(real_params), "/mqtt_client"], env=env, check=True,
                       timeout=30)
        stock = subprocess.Popen([STOCK_PYTHON, "-c", STOCK, str(args.rate)], env=env, stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        procs.append(stock)
        assert stock.stdout is not None and stock.stdin is not None
        assert stock.stdout.readline().strip() == "ready"

        def command(cmd: str) -> None:
            assert stock.stdin is not None
            stock.stdin.write(cmd + "\n")
            stock.stdin.flush()

        bridge: Optional["subprocess.Popen[Any]"] = None
        real: Optional["subprocess.Popen[Any]"] = None

        def start_bridge() -> "subprocess.Popen[Any]":
            p = subprocess.Popen([MRT_PYTHON, "-m", "micros_rt.bridges.mqtt", "--params", str(bridge_params),
                                  "--name", "micros_rt_bridge", "--print-counters", "1"], env=env,
                                 stdout=subprocess.PIPE, stderr=open(bridge_log, "w"), text=True, cwd=str(ROOT))
            procs.append(p)
            return p

        def start_real() -> "subprocess.Popen[Any]":
            p = subprocess.Popen([args.real_v1], env=env, stdout=open(real_log, "w"), stderr=subprocess.STDOUT)
            procs.append(p)
            return p

        real_started = 0.0
        if first == "bridge":
            bridge = start_bridge()
            time.sleep(gap)
            real, real_started = start_real(), time.monotonic()
        else:
            real, real_started = start_real(), time.monotonic()
            time.sleep(gap)
            bridge = start_bridge()
        # what reaches the broker on the bridge's topic (either generation), to tell where a missing text stopped
        on_broker: List[str] = []
        import paho.mqtt.client as paho
        from paho.mqtt.enums import CallbackAPIVersion

        def on_message(client: Any, userdata: Any, msg: Any) -> None:
            p = bytes(msg.payload)
            if len(p) >= 5 and p[0] in (0, 1) and struct.unpack_from("<I", p, 1 + 8 * p[0])[0] == len(p) - 5 - 8 * p[0]:
                on_broker.append(p[5 + 8 * p[0]:].decode("utf-8", "replace"))     # 1.x: [flag][stamp][String]
            elif len(p) >= 4 and struct.unpack_from("<I", p)[0] == len(p) - 4:
                on_broker.append(p[4:].decode("utf-8", "replace"))                # 2.x: [String]
        watcher = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv311)
        watcher.on_message = on_message
        watcher.connect("127.0.0.1", bport)
        watcher.subscribe("so/data", 0)
        watcher.loop_start()
        command("both")
        pub_at = real_started + 3.0
        deadline = time.monotonic() + args.duration
        published = False
        while time.monotonic() < deadline:
            if real_publishes and not published and time.monotonic() >= pub_at:
                command("real_pub")
                published = True
            time.sleep(0.1)
        time.sleep(2.0)          # what is under way arrives
        command("report")
        report = json.loads(stock.stdout.readline())
        watcher.loop_stop()
        watcher.disconnect()
        broker_texts = set(on_broker)
        missing = report.pop("missing_texts")
        report["missing_never_on_broker"] = sum(1 for x in missing if x not in broker_texts)
        real_alive = real.poll() is None
        counters: Dict[str, Any] = {}
        stop(bridge)
        assert bridge.stdout is not None
        for line in bridge.stdout.read().splitlines():
            if line.startswith("{"):
                counters = json.loads(line)
        real_code = stop(real)
        warnings = [ln.split("]: ", 1)[-1][:200] for ln in bridge_log.read_text().splitlines()
                    if "generation" in ln or "mqtt_client 1.x" in ln or "writing mqtt_client" in ln]
        aborted = [ln for ln in real_log.read_text(errors="replace").splitlines() if "terminate" in ln or "what()" in ln]
        return {"row": name, **report, "real_alive_at_end": real_alive, "real_exit": real_code,
                "real_aborted": aborted[:2], "bridge_held": counters.get("held", {}),
                "bridge_held_dropped": counters.get("bad_input", {}).get("held_dropped", 0), "bridge_sent": counters.get("sent", {}),
                "bridge_log": warnings[:4]}
    finally:
        for p in reversed(procs):
            stop(p)


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real-v1", required=True, help="the real mqtt_client 1.1.0 (ROS 1) program")
    ap.add_argument("--rate", type=float, default=50.0, help="String messages per second to the bridge")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds after the second program started")
    ap.add_argument("--rows", default="", help="comma-separated row numbers (0-based; default all)")
    ap.add_argument("--out", default=str(HERE / "results" / "mqtt_start_order.json"))
    args = ap.parse_args(argv)
    chosen = [ROWS[int(i)] for i in args.rows.split(",")] if args.rows else ROWS
    results = []
    with tempfile.TemporaryDirectory(prefix="mqtt_start_order_") as tmp:
        for i, row in enumerate(chosen):
            r = run_row(row, args, Path(tmp), i)
            results.append(r)
            print(json.dumps(r), flush=True)
    print("\n| start order | sent to the bridge | 1.1.0 republished | corrupted | missing (sent after both ran) "
          "| of those, never on the broker | 1.1.0 alive at the end |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in results:
        print(f"| {r['row']} | {r['sent']} | {r['received']} | {r['corrupted']} | "
              f"{r['missing_after_both']} of {r['sent_after_both']} | {r['missing_never_on_broker']} | "
              f"{'yes' if r['real_alive_at_end'] else 'no'} |")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                          "real_v1": args.real_v1, "rate": args.rate, "duration": args.duration,
                                          "rows": results}, indent=1) + "\n")
    print(f"\nwritten: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
