#!/usr/bin/env python3
"""mqtt_client's ping-pong demo with micros_rt's bridge: ROS -> MQTT -> ROS through a local mosquitto.

It starts what is missing, all on loopback: a rosmaster (when none answers at ROS_MASTER_URI), mosquitto on
a free port with a config file in a temporary directory, and the bridge (``python -m micros_rt.bridges.mqtt``) with
mqtt_client's demo parameters. A micros_rt node then publishes ``/ping/ros`` (std_msgs/String, stamped for
latency) and ``/ping/primitive`` (std_msgs/Int32), ``mosquitto_pub -m 69`` writes to the primitive MQTT
topic as a non-ROS device would, and the node prints what comes back on ``/pong/ros``, ``/pong/primitive``
and ``/mqtt_client/latencies/pong/ros``:

    .venv/bin/python examples/mqtt_pingpong.py [--duration 5]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import List

from demo import free_port, master_reachable, stop

PARAMS = """\
broker:
  host: 127.0.0.1
  port: {port}
bridge:
  ros2mqtt:
    - ros_topic: /ping/ros
      mqtt_topic: pingpong/ros
      inject_timestamp: true
    - ros_topic: /ping/primitive
      mqtt_topic: pingpong/primitive
      primitive: true
  mqtt2ros:
    - mqtt_topic: pingpong/ros
      ros_topic: /pong/ros
    - mqtt_topic: pingpong/primitive
      ros_topic: /pong/primitive
      primitive: true
"""


def wait_port(port: int, timeout: float = 10.0) -> bool:
    """True once something listens on 127.0.0.1:port (bounded)."""
    import socket

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.05)
    return False


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=5.0, help="seconds of ping-pong")
    args = ap.parse_args()
    os.environ.setdefault("ROS_IP", "127.0.0.1")
    os.environ.setdefault("ROS_MASTER_URI", "http://127.0.0.1:11311")
    started: List["subprocess.Popen[bytes]"] = []
    with tempfile.TemporaryDirectory(prefix="mqtt_pingpong_") as tmp:
        try:
            if not master_reachable(os.environ["ROS_MASTER_URI"]):
                port = free_port()
                os.environ["ROS_MASTER_URI"] = f"http://127.0.0.1:{port}"
                print(f"pingpong: starting rosmaster on port {port}", flush=True)
                started.append(subprocess.Popen(["/usr/bin/rosmaster", "--core", "-p", str(port)],
                                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
                if not wait_port(port, 20):
                    print("pingpong: rosmaster did not start", file=sys.stderr)
                    return 1
            mqtt_port = free_port()
            conf = Path(tmp) / "mosquitto.conf"
            conf.write_text(f"listener {mqtt_port} 127.0.0.1\nallow_anonymous true\n"
                            + ("user root\n" if os.geteuid() == 0 else ""))
            print(f"pingpong: starting mosquitto on 127.0.0.1:{mqtt_port}", flush=True)
            started.append(subprocess.Popen(["mosquitto", "-c", str(conf)], stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
            if not wait_port(mqtt_port):
                print("pingpong: mosquitto did not start", file=sys.stderr)
                return 1
            params = Path(tmp) / "params.yaml"
            params.write_text(PARAMS.format(port=mqtt_port))
            started.append(subprocess.Popen([sys.executable, "-m", "micros_rt.bridges.mqtt", "--params", str(params)]))
            return pingpong(mqtt_port, args.duration)
        finally:
            for proc in reversed(started):
                stop(proc)


def pingpong(mqtt_port: int, duration: float) -> int:
    """The ROS side: publish pings, print pongs."""
    from std_msgs.msg import Float64, Int32, String

    import micros_rt

    micros_rt.init_node("pingpong")
    nh = micros_rt.NodeHandle()
    heard = {"ros": 0, "primitive": 0}

    def on_pong(kind: str) -> "object":
        def callback(msg: object) -> None:
            heard[kind] += 1
            print(f"pong/{kind}: {getattr(msg, 'data')!r} ({type(msg)._type})", flush=True)  # type: ignore[attr-defined]
        return callback

    nh.subscribe("/pong/ros", String, on_pong("ros"), 10)
    nh.subscribe("/pong/primitive", Int32, on_pong("primitive"), 10)
    nh.subscribe("/mqtt_client/latencies/pong/ros", Float64,
                 lambda m: print(f"latency of /pong/ros: {m.data * 1000:.1f} ms", flush=True), 10)
    ping_ros = nh.advertise("/ping/ros", String, 10)
    ping_primitive = nh.advertise("/ping/primitive", Int32, 10)
    deadline = time.monotonic() + 15
    while ping_ros.get_num_connections() < 1 or ping_primitive.get_num_connections() < 1:   # the bridge
        if time.monotonic() > deadline:
            print("pingpong: the bridge did not subscribe", file=sys.stderr)
            return 1
        time.sleep(0.05)
    end, i = time.monotonic() + duration, 0
    while time.monotonic() < end and micros_rt.ok():
        ping_ros.publish(String(data=f"Hello MQTT {i}"))
        ping_primitive.publish(Int32(data=42))
        if i == 2:   # a non-ROS device on the primitive topic
            subprocess.run(["mosquitto_pub", "-h", "127.0.0.1", "-p", str(mqtt_port), "-t", "pingpong/primitive",
                            "-m", "69"], check=False, timeout=10)
        i += 1
        time.sleep(1.0)
    time.sleep(0.5)
    print(f"pingpong: sent {i} pings, heard {heard['ros']} on /pong/ros and {heard['primitive']} on "
          f"/pong/primitive", flush=True)
    micros_rt.shutdown()
    return 0 if heard["ros"] and heard["primitive"] else 1


if __name__ == "__main__":
    sys.exit(main())
