"""mcu-bridge with real processes on loopback: the C microcontroller stand-in (built here with gcc against
Debian's libmsgpack-dev), the bridge (``python -m micros_rt.bridges.mcu``), micros_rt and stock ROS peers.

The board is 127.0.0.2, the bridge 127.0.0.1; every test picks its own free ports and topic names.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import msgpack
import pytest
import yaml

import harness

sys.path.insert(0, str(harness.PEERS_DIR))
import mcu_harness  # noqa: E402
from mcu_harness import Ports, bridge_argv, mrt_peer_argv, standin_argv, wait_stats, write_config  # noqa: E402

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def standin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return mcu_harness.build_standin(tmp_path_factory.mktemp("mcu_standin"))


def start_bridge(spawn: harness.Spawner, tmp_path: Path, ports: Ports, body: str, node: str) -> harness.Peer:
    bridge = spawn(bridge_argv(write_config(tmp_path, ports, body), node), name=node)
    bridge.wait_for("ready", 60)
    return bridge


def test_imu_stream_at_100_hz_heard_by_micros_rt_listener_and_rostopic_echo(
        standin: Path, ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    ports = Ports.pick()
    bridge = start_bridge(spawn, tmp_path, ports, "stats_period: 0.5\nfrom_microcontroller:\n"
                          "  - {topic: /mcu_a/imu, type: sensor_msgs/Imu, name: imu}\n", "mcu_bridge_a")
    listener = spawn(mrt_peer_argv("listen", "--topic", "/mcu_a/imu", "--type", "sensor_msgs/Imu", "--full-msg",
                                   "--queue-size", 1000, "--duration", 60, "--node-name", "mcu_a_listener"))
    listener.wait_for("ready", 60)
    echo = spawn([harness.STOCK_PYTHON, harness.ROSTOPIC, "echo", "-n", "3", "/mcu_a/imu"], name="rostopic echo")
    harness.wait_until(lambda: mcu_harness.connections(ros_master, "/mcu_bridge_a", "/mcu_a/imu") >= 2, 60,
                       interval=0.2, message="the micros_rt listener and rostopic echo to connect to the bridge")
    board = spawn(standin_argv(standin, ports, "--rate", 100, "--count", 300, "--linger", 1, "--duration", 60))
    board.wait_for("sent", 60)
    stats = wait_stats(bridge, lambda s: s["from_microcontroller"]["imu"]["published"] >= 300, 30)
    harness.wait_until(lambda: listener.count("recv") >= 300, 30, message="300 Imu messages at the listener")
    recv = listener.events("recv")
    first_t, last_t = recv[0]["t"], recv[-1]["t"]
    z = [round(e["msg"]["angular_velocity"]["z"], 6) for e in recv]
    print(f"\nC board -> bridge -> micros_rt listener: {len(recv)}/300 Imu at "
          f"{(len(recv) - 1) / max(last_t - first_t, 1e-9):.0f} Hz over {sorted({e['transport'] for e in recv})}, "
          f"{len(z) - len(set(z))} duplicates; bridge counters {stats['from_microcontroller']['imu']}")
    assert {e["transport"] for e in recv} == {"SHM"}   # the bridge and the listener share this host
    assert sorted(set(z)) == [round(0.001 * i, 6) for i in range(300)] and len(z) == 300
    msg = recv[10]["msg"]
    assert msg["header"]["frame_id"] == "imu_link" and msg["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert msg["angular_velocity"]["x"] == 0.5 and msg["angular_velocity"]["y"] == -0.25
    assert msg["linear_acceleration"] == {"x": 0.0, "y": 0.0, "z": 9.81}
    assert msg["orientation_covariance"] == [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01]
    assert msg["header"]["stamp"]["secs"] > 1_600_000_000
    assert stats["bad_input"]["total"] == 0
    assert echo.wait(30) == 0
    printed = "\n".join(e["line"] for e in echo.events("_raw"))
    docs = [yaml.safe_load(d) for d in printed.split("---") if d.strip()]
    print(f"stock rostopic echo: {len(docs)} messages, e.g. linear_acceleration {docs[0]['linear_acceleration']}")
    assert len(docs) == 3
    assert all(d["header"]["frame_id"] == "imu_link" and d["linear_acceleration"]["z"] == 9.81 for d in docs)
    assert docs[0]["angular_velocity_covariance"] == [0.02, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.02]


def test_twist_commands_reach_the_c_board_field_for_field_and_oversized_is_refused(
        standin: Path, ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    ports = Ports.pick()
    bridge = start_bridge(spawn, tmp_path, ports, "stats_period: 0.5\nto_microcontroller:\n"
                          "  - {topic: /mcu_b/cmd_vel, type: geometry_msgs/Twist, name: cmd_vel,"
                          " qos: {transport_priority: HIGH}}\n"
                          "  - {topic: /mcu_b/text, type: std_msgs/String, name: text}\n", "mcu_bridge_b")
    board = spawn(standin_argv(standin, ports, "--rate", 0, "--duration", 90))
    board.wait_for("ready", 10)
    twist = {"linear": {"x": 0.25, "y": -1.5, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 3.0}}
    talker = spawn(mrt_peer_argv("talk", "--topic", "/mcu_b/cmd_vel", "--type", "geometry_msgs/Twist",
                                 "--data-json", json.dumps(twist), "--count", 20, "--rate", 20,
                                 "--wait-subscribers", 1, "--linger", 0.5,
                                 "--node-name", "mcu_b_talker"))
    big = spawn(mrt_peer_argv("talk", "--topic", "/mcu_b/text", "--data-json", json.dumps({"data": "x" * 2000}),
                              "--count", 2, "--rate", 5, "--wait-subscribers", 1,
                              "--linger", 0.5,
                              "--node-name", "mcu_b_big"))
    assert talker.wait(60) == 0 and big.wait(60) == 0
    small = spawn(mrt_peer_argv("talk", "--topic", "/mcu_b/text", "--data-json", json.dumps({"data": "small {i}"}),
                                "--count", 2, "--rate", 5, "--wait-subscribers", 1,
                              "--linger", 0.5,
                                "--node-name", "mcu_b_small"))
    assert small.wait(60) == 0
    harness.wait_until(lambda: len([e for e in board.events("recv") if e["name"] == "text"]) >= 2, 20,
                       message="the small texts at the board")
    stats = wait_stats(bridge, lambda s: s["to_microcontroller"]["text"]["oversized"] == 2
                       and s["to_microcontroller"]["text"]["sent"] == 2, 20)
    commands = [e for e in board.events("recv") if e["name"] == "cmd_vel"]
    texts = [e for e in board.events("recv") if e["name"] == "text"]
    refusal = [line for line in bridge.stderr_tail(200).splitlines() if "/mcu_b/text: the message encodes" in line]
    print(f"\nmicros_rt talker -> bridge -> C board: {len(commands)}/20 Twist, e.g. {commands[0]['fields']} "
          f"with IP TOS {commands[0]['tos']}; texts at the board {[t['fields'] for t in texts]}; "
          f"bridge counters {stats['to_microcontroller']}; "
          f"the bridge said: {refusal[0].split('micros_rt: ')[-1][:160]}")
    assert len(commands) == 20
    # CVRA's final form (the default): [name, args], the fields in definition order, nested messages as arrays
    positional = [[0.25, -1.5, 0.0], [0.0, 0.0, 3.0]]
    assert all(c["fields"] == positional and c["tos"] == 34 << 2 for c in commands)  # HIGH = DSCP AF41
    assert [t["fields"] for t in texts] == ["small 0", "small 1"]   # one field: its value bare
    assert all(t["tos"] == 0 for t in texts) and max(e["bytes"] for e in board.events("recv")) <= 1472
    assert stats["to_microcontroller"]["cmd_vel"]["sent"] == 20
    assert stats["to_microcontroller"]["text"] == {"sent": 2, "oversized": 2, "expired": 0, "filtered": 0,
                                                   "send_failed": 0}
    # [text, "x" * 2000]: 92, a4 "text", da 07d0, 2,000 bytes (2,015 in the map form)
    assert len(refusal) == 1 and "2,009 bytes" in refusal[0] and "mtu of 1,472" in refusal[0]


def test_services_both_ways_with_rosservice_and_the_c_board(
        standin: Path, ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    ports = Ports.pick()
    server = spawn([harness.STOCK_PYTHON, str(mcu_harness.ROS_SERVICE_PEER), "--service", "/mcu_c/set_mode"])
    server.wait_for("ready", 60)
    # the stand-in's --array-form streams mid-2015's [name, f1, ...] while its server reads only the final
    # form's [name, args] (CVRA's C service_call.c): no CVRA era mixes them, so this board needs wire_form
    bridge = start_bridge(spawn, tmp_path, ports, "stats_period: 0.5\nwire_form: final\n"
                          "from_microcontroller:\n  - {topic: /mcu_c/imu, type: sensor_msgs/Imu, name: imu,"
                          " qos: {time_filter_duration: 0.1}}\n"
                          "services_on_microcontroller:\n"
                          "  - {service: /mcu_c/reset, type: std_srvs/Trigger, name: reset}\n"
                          "  - {service: /mcu_c/slow, type: std_srvs/Trigger, name: slow, timeout: 0.5}\n"
                          "services_for_microcontroller:\n"
                          "  - {service: /mcu_c/set_mode, type: std_srvs/SetBool, name: set_mode}\n", "mcu_bridge_c")
    board = spawn(standin_argv(standin, ports, "--rate", 50, "--array-form", "--hang-name", "slow",
                             "--call", "set_mode", "--call-arg", "true", "--call-after", 0.5, "--duration", 90))
    result = board.wait_for("call_result", 30)
    called = server.wait_for("called", 10)
    reset = mcu_harness.rosservice(ros_master, "call", "/mcu_c/reset")
    slow = mcu_harness.rosservice(ros_master, "call", "/mcu_c/slow")
    reset_again = mcu_harness.rosservice(ros_master, "call", "/mcu_c/reset")
    stats = wait_stats(bridge, lambda s: s["services_on_microcontroller"]["reset"]["ok"] == 2, 20)
    print(f"\nC board calls the rospy service through the bridge: {result['response']} in {result['seconds']} s; "
          f"rosservice call /mcu_c/reset: {reset.stdout.strip()!r}; /mcu_c/slow: {slow.stderr.strip()[-140:]!r}; "
          f"counters {stats['services_on_microcontroller']} {stats['services_for_microcontroller']}; "
          f"array-form Imu at 50 Hz with time_filter_duration 0.1: {stats['from_microcontroller']['imu']}")
    # the answer as CVRA's handlers answer: [success, message]
    assert result["response"] == [True, "mode on"] and called["data"] is True
    assert reset.returncode == 0 and "success: True" in reset.stdout and 'message: "reset done (1)"' in reset.stdout
    assert reset_again.returncode == 0 and "reset done (2)" in reset_again.stdout
    assert slow.returncode != 0
    assert "did not answer /mcu_c/slow ('slow') within 0.5 s" in slow.stdout + slow.stderr
    assert stats["services_on_microcontroller"]["slow"]["timeout"] == 1
    assert stats["services_for_microcontroller"]["set_mode"] == {"calls": 1, "ok": 1, "failed": 0}
    imu = stats["from_microcontroller"]["imu"]  # array form, 50 Hz, at most one per 0.1 s published
    assert imu["published"] > 0 and imu["filtered"] > 0 and imu["published"] <= imu["received"] / 3
    assert stats["bad_input"]["total"] == 0
    served = board.events("served")
    # CVRA's final form both ways: the board's call was [set_mode, [true]], the bridge's calls [reset, nil]
    assert [s["name"] for s in served] == ["reset", "slow", "reset"] and served[0]["params"] is None


def test_a_board_speaking_the_readme_form_with_wire_form_readme(
        standin: Path, ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    """wire_form: readme keeps the seed README's form working: topics as name then {fields} both ways, service
    requests as the name then {fields} (two objects in one frame) both ways; a board in that form understands
    nothing else."""
    ports = Ports.pick()
    server = spawn([harness.STOCK_PYTHON, str(mcu_harness.ROS_SERVICE_PEER), "--service", "/mcu_r/set_mode"])
    server.wait_for("ready", 60)
    bridge = start_bridge(spawn, tmp_path, ports, "stats_period: 0.5\nwire_form: readme\n"
                          "from_microcontroller:\n  - {topic: /mcu_r/imu, type: sensor_msgs/Imu, name: imu}\n"
                          "to_microcontroller:\n  - {topic: /mcu_r/text, type: std_msgs/String, name: text}\n"
                          "services_on_microcontroller:\n  - {service: /mcu_r/reset, type: std_srvs/Trigger,"
                          " name: reset}\n"
                          "services_for_microcontroller:\n"
                          "  - {service: /mcu_r/set_mode, type: std_srvs/SetBool, name: set_mode}\n", "mcu_bridge_r")
    board = spawn(standin_argv(standin, ports, "--form", "readme", "--rate", 20, "--call", "set_mode",
                               "--call-key", "data", "--call-arg", "true", "--call-after", 0.5, "--duration", 90))
    result = board.wait_for("call_result", 30)
    called = server.wait_for("called", 10)
    reset = mcu_harness.rosservice(ros_master, "call", "/mcu_r/reset")
    talker = spawn(mrt_peer_argv("talk", "--topic", "/mcu_r/text", "--data-json", json.dumps({"data": "r {i}"}),
                                 "--count", 3, "--rate", 5, "--wait-subscribers", 1,
                                 "--linger", 0.5, "--node-name", "mcu_r_talker"))
    assert talker.wait(60) == 0
    harness.wait_until(lambda: len(board.events("recv")) >= 3, 20, message="3 texts at the README-form board")
    stats = wait_stats(bridge, lambda s: s["from_microcontroller"]["imu"]["published"] >= 10
                       and s["to_microcontroller"]["text"]["sent"] == 3, 30)
    texts = board.events("recv")
    served = board.events("served")
    print(f"\nREADME-form board: call {result['response']}; rosservice call /mcu_r/reset: {reset.stdout.strip()!r}, "
          f"the board got {served}; texts at the board {[(t['name'], t['fields']) for t in texts]}; "
          f"imu {stats['from_microcontroller']['imu']}")
    assert result["response"] == [True, "mode on"] and called["data"] is True
    assert reset.returncode == 0 and "reset done (1)" in reset.stdout
    assert [(s["name"], s["params"]) for s in served] == [("reset", {})]   # "reset" then {}: an empty request
    assert [(t["name"], t["fields"]) for t in texts] == [("text", {"data": f"r {i}"}) for i in range(3)]
    assert stats["bad_input"]["total"] == 0


def _malformed(kind: str, i: int) -> bytes:
    good = {"header": {"seq": i, "stamp": [1, 0], "frame_id": "x"}, "orientation": [0, 0, 0, 1],
            "orientation_covariance": [0.0] * 9, "angular_velocity": [0, 0, 0],
            "angular_velocity_covariance": [0.0] * 9, "linear_acceleration": [0, 0, 0],
            "linear_acceleration_covariance": [0.0] * 9}
    if kind == "not_msgpack":
        return b"\xc1" + i.to_bytes(4, "big")
    if kind == "bad_shape":
        return bytes(msgpack.packb([i, "imu"]))
    if kind == "unknown_stream":
        return bytes(msgpack.packb(f"imu{i}") + msgpack.packb(good))
    if kind == "missing_field":
        return bytes(msgpack.packb("imu") + msgpack.packb({k: v for k, v in good.items() if k != "header"}))
    good["orientation"] = [0, 0, "tilted", 1]
    return bytes(msgpack.packb("imu") + msgpack.packb(good))


def test_1000_malformed_datagrams_and_bad_frames_bridge_keeps_serving(
        standin: Path, ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    ports = Ports.pick()
    bridge = start_bridge(spawn, tmp_path, ports, "stats_period: 0.2\n"
                          "from_microcontroller:\n  - {topic: /mcu_d/imu, type: sensor_msgs/Imu, name: imu}\n"
                          "services_on_microcontroller:\n  - {service: /mcu_d/reset, type: std_srvs/Trigger,"
                          " name: reset}\n"
                          "services_for_microcontroller:\n  - {service: /mcu_d/set_mode, type: std_srvs/SetBool}\n",
                          "mcu_bridge_d")
    board = spawn(standin_argv(standin, ports, "--rate", 50, "--duration", 120))
    board.wait_for("ready", 10)
    wait_stats(bridge, lambda s: s["from_microcontroller"]["imu"]["published"] > 10, 30)
    kinds = ["not_msgpack", "bad_shape", "unknown_stream", "missing_field", "bad_field"]
    t0 = time.monotonic()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as evil:
        evil.bind((ports.board, 0))  # from the board's address: the bridge drops strangers before parsing
        for batch in range(10):  # paced by the bridge's own counters, so the kernel's buffer never overflows
            for i in range(100):
                evil.sendto(_malformed(kinds[i % 5], batch * 100 + i), (ports.bridge, ports.bridge_topic))
            wait_stats(bridge, lambda s: s["bad_input"]["total"] >= 100 * (batch + 1), 30)
    frames = {"bad_crc": bytes.fromhex("91a5726573657400000000c0"),      # ["reset"] with a zero CRC
              "no_end": bytes.fromhex("91a57265736574") + b"\x0b\xbd\x6a\xfb"}  # closed before END
    for i in range(200):
        kind = "bad_crc" if i % 2 == 0 else "no_end"
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as conn:
            conn.bind((ports.board, 0))
            conn.settimeout(10)
            conn.connect((ports.bridge, ports.bridge_service))
            conn.sendall(frames[kind])
            if kind == "no_end":
                conn.shutdown(socket.SHUT_WR)
            assert conn.recv(100) == b""  # the bridge answers nothing and closes
    flood_seconds = time.monotonic() - t0
    after = wait_stats(bridge, lambda s: s["bad_input"]["total"] >= 1200, 30)
    published_then = after["from_microcontroller"]["imu"]["published"]
    later = wait_stats(bridge, lambda s: s["from_microcontroller"]["imu"]["published"] >= published_then + 25, 30)
    reset = mcu_harness.rosservice(ros_master, "call", "/mcu_d/reset")
    echo = harness.rostopic(ros_master, "echo", "-n", "1", "/mcu_bridge_d/stats", timeout=30)
    on_topic = json.loads(yaml.safe_load(echo.stdout.split("---")[0])["data"])
    warnings = [line for line in bridge.stderr_tail(200).splitlines() if "microcontroller link:" in line]
    print(f"\n1,000 malformed datagrams + 200 bad frames in {flood_seconds:.1f} s: bad_input {after['bad_input']}; "
          f"{len(warnings)} warning lines; Imu kept flowing ({published_then} -> "
          f"{later['from_microcontroller']['imu']['published']} published); rosservice call after: "
          f"{reset.stdout.strip()!r}; ~stats via rostopic echo: bad_input.total {on_topic['bad_input']['total']}")
    for line in warnings:
        print("  ", line.split("micros_rt: ")[-1][:200])
    assert after["bad_input"] == {"not_msgpack": 200, "bad_shape": 200, "unknown_stream": 200, "missing_field": 200,
                                  "bad_field": 200, "bad_crc": 100, "no_end": 100, "total": 1200}
    assert len(warnings) == 7  # one per peer and kind, the rest counted
    assert reset.returncode == 0 and "success: True" in reset.stdout
    assert on_topic["bad_input"]["total"] == 1200 and bridge.alive()


def test_cli_refuses_reliable_delivery_and_a_busy_port_in_one_line(
        ros_master: harness.RosMaster, tmp_path: Path) -> None:
    ports = Ports.pick()
    reliable = write_config(tmp_path, ports, "from_microcontroller:\n  - topic: /mcu_e/imu\n"
                            "    type: sensor_msgs/Imu\n    qos: {deadline: 0.5, using_best_effort_protocol: false}\n",
                            "reliable.yaml")
    cli = str(Path(harness.MICROS_RT_PYTHON).parent / "micros-rt")
    cp = subprocess.run([cli, "mcu-bridge", "--config", str(reliable)], env=ros_master.env, capture_output=True,
                        text=True, timeout=60)
    print(f"\n{cp.stderr.strip()}")
    assert cp.returncode == 1 and len(cp.stderr.strip().splitlines()) == 1
    assert cp.stderr.startswith(f"micros-rt mcu-bridge: {reliable}:6: from_microcontroller[0].qos."
                                f"using_best_effort_protocol: reliable delivery (false) cannot be given")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind((ports.bridge, ports.bridge_topic))
        fine = write_config(tmp_path, ports, "", "fine.yaml")
        cp = subprocess.run([harness.MICROS_RT_PYTHON, "-m", "micros_rt.bridges.mcu", "--config", str(fine), "--name",
                             "mcu_bridge_e"], env=ros_master.env, capture_output=True, text=True, timeout=60)
    print(cp.stderr.strip())
    assert cp.returncode == 1 and "Traceback" not in cp.stderr
    assert f"cannot bind UDP {ports.bridge}:{ports.bridge_topic} for topics: Address already in use" in cp.stderr
