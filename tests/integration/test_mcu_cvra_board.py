"""mcu-bridge against a board that sends exactly what CVRA's code sent (issue 37, items 5-9), through the real
bridge process, stock rosservice, a stock rospy service and a micros_rt listener, on loopback.

The board (tests/peers/mcu_cvra_board.py) replays the bytes in tests/fixtures/cvra/, captured from CVRA's
cvra_rpc at the commits named there: final-era list arguments, bare and nil answers, a connection closed
without an answer, and the seed README era's two-object request.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Dict

import pytest

import harness

sys.path.insert(0, str(harness.PEERS_DIR))
import mcu_harness  # noqa: E402
from mcu_harness import Ports, bridge_argv, mrt_peer_argv, wait_stats, write_config  # noqa: E402

pytestmark = pytest.mark.integration

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "cvra"
CVRA_BOARD = harness.PEERS_DIR / "mcu_cvra_board.py"


def fixture_hex(stem: str, key: str) -> str:
    data: Dict[str, Any] = json.loads((FIXTURES / f"{stem}.json").read_text())
    e = next(e for e in data["entries"] if e["id"] == key)
    return str(e["hex"])


def test_a_cvra_board_of_each_era_through_the_bridge(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                     tmp_path: Path) -> None:
    ports = Ports.pick()
    server = spawn([harness.STOCK_PYTHON, str(mcu_harness.ROS_SERVICE_PEER), "--service", "/mcu_f/set_mode"])
    server.wait_for("ready", 60)
    bridge = spawn(bridge_argv(write_config(tmp_path, ports, (
        "stats_period: 0.3\n"
        "from_microcontroller:\n  - {topic: /mcu_f/odometry, type: geometry_msgs/Pose2D, name: odometry_raw}\n"
        "to_microcontroller:\n  - {topic: /mcu_f/cmd_vel, type: geometry_msgs/Twist, name: cmd_vel}\n"
        "services_on_microcontroller:\n"
        "  - {service: /mcu_f/ping, type: std_srvs/Trigger, name: ping}\n"
        "  - {service: /mcu_f/arm, type: std_srvs/Trigger, name: arm}\n"
        "  - {service: /mcu_f/nothing, type: std_srvs/Trigger, name: nothing}\n"
        "  - {service: /mcu_f/lvl, type: roscpp/SetLoggerLevel, name: lvl}\n"
        "  - {service: /mcu_f/gone, type: roscpp/SetLoggerLevel, name: gone}\n"
        "  - {service: /mcu_f/gone_trigger, type: std_srvs/Trigger, name: gone_trigger}\n"
        "services_for_microcontroller:\n  - {service: /mcu_f/set_mode, type: std_srvs/SetBool, name: set_mode}\n")),
        "mcu_bridge_f"), name="mcu_bridge_f")
    bridge.wait_for("ready", 60)
    listener = spawn(mrt_peer_argv("listen", "--topic", "/mcu_f/odometry", "--type", "geometry_msgs/Pose2D",
                                   "--full-msg", "--duration", 90, "--node-name", "mcu_f_listener"))
    listener.wait_for("ready", 60)
    harness.wait_until(lambda: mcu_harness.connections(ros_master, "/mcu_bridge_f", "/mcu_f/odometry") >= 1, 60,
                       interval=0.2, message="the micros_rt listener to connect to the bridge")
    odometry = fixture_hex("final_babf2cfa", "topic_odometry_raw")   # ["odometry_raw", [1.5, 2.5, 0.5]]
    two_objects = fixture_hex("readme_0670b782", "call_set_mode_map")  # "set_mode" {"data": true}, one frame
    bare = fixture_hex("final_babf2cfa", "call_set_mode_bare")        # ["set_mode", true]
    board = spawn([harness.MICROS_RT_PYTHON, str(CVRA_BOARD), *ports.standin_args(), "--stream", odometry,
                   "--rate", "20", "--count", "40",
                   "--answer", f"ping={fixture_hex('final_babf2cfa', 'answer_pong')}",
                   "--answer", f"arm={fixture_hex('final_babf2cfa', 'answer_true')}",
                   "--answer", f"nothing={fixture_hex('final_babf2cfa', 'c_answer_nil')}",
                   "--answer", f"lvl={fixture_hex('final_babf2cfa', 'c_answer_nil')}",
                   "--answer", "gone=close", "--answer", "gone_trigger=close",
                   "--call", two_objects, "--call", bare, "--call-after", "0.3", "--duration", "90"], name="cvra board")
    board.wait_for("ready", 30)
    results = board.wait_for_count("call_result", 2, 30)
    board.wait_for("sent", 30)
    stats = wait_stats(bridge, lambda s: s["from_microcontroller"]["odometry_raw"]["published"] >= 40, 30)
    harness.wait_until(lambda: listener.count("recv") >= 40, 30, message="40 Pose2D at the listener")
    calls = {name: mcu_harness.rosservice(ros_master, "call", f"/mcu_f/{name}", *extra)
             for name, extra in (("ping", ()), ("arm", ()), ("nothing", ()), ("lvl", ("ros", "debug")),
                                 ("gone", ("ros", "debug")), ("gone_trigger", ()))}
    talker = spawn(mrt_peer_argv("talk", "--topic", "/mcu_f/cmd_vel", "--type", "geometry_msgs/Twist",
                                 "--data-json", json.dumps({"linear": {"x": 0.25}, "angular": {"z": -0.5}}),
                                 "--count", 3, "--rate", 10, "--wait-subscribers", 1,
                                 "--linger", 0.5, "--node-name", "mcu_f_talker"))
    assert talker.wait(60) == 0
    harness.wait_until(lambda: len(board.events("recv")) >= 3, 20, message="3 Twist commands at the board")
    after = wait_stats(bridge, lambda s: s["services_on_microcontroller"]["gone_trigger"]["failed"] == 1, 20)
    served = [(s["name"], s["rest"]) for s in board.events("served")]
    poses = {(e["msg"]["x"], e["msg"]["y"], e["msg"]["theta"]) for e in listener.events("recv")}
    print(f"\nCVRA-era board through the bridge: {listener.count('recv')} Pose2D {poses} from {odometry}; "
          f"its calls {[(r['request'], r['decoded']) for r in results]}; served {served}; Twist at the board "
          f"{board.events('recv')[0]['decoded']}; counters {after['services_on_microcontroller']}")
    for name, cp in calls.items():
        print(f"  rosservice call /mcu_f/{name}: rc {cp.returncode} {(cp.stdout + cp.stderr).strip()[-220:]!r}")
    # item 5: list arguments publish the Pose2D, every message
    assert stats["from_microcontroller"]["odometry_raw"]["received"] == 40 and stats["bad_input"]["total"] == 0
    assert poses == {(1.5, 2.5, 0.5)}
    # item 7: the README era's two-object request and the final era's bare one both reach the rospy service;
    # the answer is CVRA's shape, [success, message]
    assert [r["request"] for r in results] == [two_objects, bare]
    assert [r["decoded"] for r in results] == [[[True, "mode on"]]] * 2
    assert [e["data"] for e in server.events("called")] == [True, True]
    # item 6: bare and nil answers
    assert calls["ping"].returncode == 0 and "success: True" in calls["ping"].stdout
    assert 'message: "pong"' in calls["ping"].stdout
    assert calls["arm"].returncode == 0 and "success: True" in calls["arm"].stdout
    assert calls["nothing"].returncode == 0 and "success: False" in calls["nothing"].stdout
    assert "answered nil" in calls["nothing"].stdout
    assert calls["lvl"].returncode == 0
    # item 8: closed without an answer is an error for the empty response type too
    for name in ("gone", "gone_trigger"):
        out = calls[name].stdout + calls[name].stderr
        assert calls[name].returncode != 0, out
        assert f"closed the connection without answering /mcu_f/{name} ('{name}')" in out
    assert after["services_on_microcontroller"]["gone"] == {"calls": 1, "ok": 0, "failed": 1, "timeout": 0}
    # item 9: the board got positional arguments, as CVRA's clients send them
    assert dict(served)["ping"] == [None] and dict(served)["lvl"] == [["ros", "debug"]]
    assert board.events("recv")[0]["decoded"] == [["cmd_vel", [[0.25, 0.0, 0.0], [0.0, 0.0, -0.5]]]]
    assert after["services_for_microcontroller"]["set_mode"] == {"calls": 2, "ok": 2, "failed": 0}
    assert after["bad_input"]["total"] == 0 and bridge.alive()


def test_boards_of_older_eras_are_called_in_their_own_form_without_wire_form(
        ros_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    """Issue 44: no wire_form. A mid-2015 board that streams its Pose2D as [name, x, y, theta] and a seed-README
    board whose call is "set_mode" then {"data": true} are then called in their own form: the mid-2015 handler
    gets [] for reset and ["ros", "warn"] for set_logger_level (CVRA's final form gave it [None] and
    [["ros", "warn"]]); the README board's server unpacks name and params (the final form's one object made it
    raise ValueError and close, a ServiceException at the ROS caller)."""
    services = ("services_on_microcontroller:\n"
                "  - {service: /%(ns)s/reset, type: std_srvs/Trigger, name: reset}\n"
                "  - {service: /%(ns)s/enable, type: std_srvs/SetBool, name: enable}\n"
                "  - {service: /%(ns)s/lvl, type: roscpp/SetLoggerLevel, name: set_logger_level}\n")
    answers = ["--answer", "reset=c3", "--answer", "enable=c3", "--answer", "set_logger_level=c0"]
    server = spawn([harness.STOCK_PYTHON, str(mcu_harness.ROS_SERVICE_PEER), "--service", "/mcu_r/set_mode"])
    mid_ports, readme_ports = Ports.pick(), Ports.pick()
    mid_bridge = spawn(bridge_argv(write_config(tmp_path, mid_ports, (
        "stats_period: 0.3\n"
        "from_microcontroller:\n  - {topic: /mcu_m/odometry, type: geometry_msgs/Pose2D, name: odometry_raw}\n"
        + services % {"ns": "mcu_m"}), "mid.yaml"), "mcu_bridge_m"), name="mcu_bridge_m")
    readme_bridge = spawn(bridge_argv(write_config(tmp_path, readme_ports, (
        "stats_period: 0.3\n" + services % {"ns": "mcu_r"}
        + "services_for_microcontroller:\n  - {service: /mcu_r/set_mode, type: std_srvs/SetBool, name: set_mode}\n"),
        "readme.yaml"), "mcu_bridge_r"), name="mcu_bridge_r")
    server.wait_for("ready", 60)
    mid_bridge.wait_for("ready", 60)
    readme_bridge.wait_for("ready", 60)
    mid_board = spawn([harness.MICROS_RT_PYTHON, str(CVRA_BOARD), *mid_ports.standin_args(), "--era", "mid2015",
                       "--stream", fixture_hex("mid2015_feb95469", "topic_odometry_raw"), "--rate", "20",
                       "--count", "5", *answers, "--duration", "90"], name="mid2015 board")
    readme_board = spawn([harness.MICROS_RT_PYTHON, str(CVRA_BOARD), *readme_ports.standin_args(), "--era", "readme",
                          "--call", fixture_hex("readme_0670b782", "call_set_mode_map"), "--call-after", "0.3",
                          *answers, "--duration", "90"], name="readme board")
    # what the board sent names its era (until then the bridge writes the final form)
    wait_stats(mid_bridge, lambda s: s["from_microcontroller"]["odometry_raw"]["published"] >= 5, 30)
    assert readme_board.wait_for("call_result", 30)["decoded"] == [[True, "mode on"]]
    calls = {(ns, name): mcu_harness.rosservice(ros_master, "call", f"/{ns}/{name}", *extra)
             for ns in ("mcu_m", "mcu_r")
             for name, extra in (("reset", ()), ("enable", ("true",)), ("lvl", ("rosout", "warn")))}
    mid_served = {e["name"]: e["args"] for e in mid_board.wait_for_count("served", 3, 30)}
    readme_served = {e["name"]: e["args"] for e in readme_board.wait_for_count("served", 3, 30)}
    mid_stats, readme_stats = mcu_harness.latest_stats(mid_bridge), mcu_harness.latest_stats(readme_bridge)
    print(f"\nno wire_form: mid2015 board learned ({mid_stats.get('link')}), its handlers got {mid_served}; "
          f"readme board learned ({readme_stats.get('link')}), its handlers got {readme_served}")
    for key, cp in calls.items():
        print(f"  rosservice call /{key[0]}/{key[1]}: rc {cp.returncode} {(cp.stdout + cp.stderr).strip()[-160:]!r}")
    assert mid_served == {"reset": [], "enable": [True], "set_logger_level": ["rosout", "warn"]}
    assert readme_served == {"reset": {}, "enable": {"data": True},
                             "set_logger_level": {"logger": "rosout", "level": "warn"}}
    assert all(e["handled"] for e in mid_board.events("served") + readme_board.events("served"))
    for (ns, name), cp in calls.items():
        assert cp.returncode == 0, (ns, name, cp.stdout + cp.stderr)
        if name != "lvl":
            assert "success: True" in cp.stdout
    assert mid_stats["link"] == {"wire_form": "mid2015", "wire_form_changes": 1}
    assert readme_stats["link"] == {"wire_form": "readme", "wire_form_changes": 1}
    assert mid_bridge.alive() and readme_bridge.alive()
