"""``micros-rt run``: unmodified rospy scripts (tests/peers/plain_*.py) on micros_rt, with real processes.

Two plain scripts run this way talk DDS (no TCP link between them in the kernel's socket table) and
TCPROS with stock rospy nodes and ``rostopic``; a YAML profile gives an unmodified subscriber a time
filter; services, parameters, timers, time and ``wait_for_message`` keep working; an unmodified
``rospy.Service``/``ServiceProxy`` and actionlib ``SimpleActionClient`` reach ROS 2 (rclpy peers); the script's
``__name__``, ``sys.argv``, ``sys.path[0]``, remappings, traceback and exit code are its own.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any, Dict, List, Optional

import pytest

import harness
from helpers import bus_info, data_links_between, received, tcp_links_between, transports

MICROS_RT = str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt")
PLAIN_TALKER = str(harness.PEERS_DIR / "plain_talker.py")
PLAIN_LISTENER = str(harness.PEERS_DIR / "plain_listener.py")
PLAIN_PROBE = str(harness.PEERS_DIR / "plain_probe.py")
PLAIN_SERVICE = str(harness.PEERS_DIR / "plain_service.py")
ROS2_SERVICE_PEER = str(harness.PEERS_DIR / "ros2_service_peer.py")
PLAIN_ACTION_CLIENT = str(harness.PEERS_DIR / "plain_action_client.py")
ROS2_ACTION_PEER = str(harness.PEERS_DIR / "ros2_action_peer.py")


ROS1_ACTION_PEER = str(harness.PEERS_DIR / "ros1_action_peer.py")


def user_defaults(env: Dict[str, str]) -> Dict[str, str]:
    """``env`` with what users get: shared memory and ROS 2 visibility auto (the suite's harness sets other modes)."""
    return {k: v for k, v in env.items() if k not in ("MICROS_RT_DISABLE_SHM", "MICROS_RT_ROS2")}


def run(script: str, *args: str, profile: Optional[Path] = None, hints: Optional[str] = None) -> List[str]:
    """``micros-rt run [--profile P] [--hints H] SCRIPT ARGS...``"""
    argv = [MICROS_RT, "run"]
    if profile is not None:
        argv += ["--profile", str(profile)]
    if hints is not None:
        argv += ["--hints", hints]
    return argv + [script, *args]


def stock(script: str, *args: str) -> List[str]:
    """The same plain script as a stock rospy node."""
    return [harness.STOCK_PYTHON, script, *args]


def links_of(master: harness.RosMaster, node: str, topic: str) -> Dict[str, str]:
    """getBusInfo of ``node`` for ``topic``: peer (caller id or URI) -> transport."""
    return {str(c[1]): str(c[3]) for c in bus_info(master, node) if c[4] == topic}


def test_two_plain_scripts_talk_shm_and_tcpros_with_stock_nodes(ros_master: harness.RosMaster,
                                                                spawn: harness.Spawner) -> None:
    topic = "/run_chatter"
    listener = spawn(run(PLAIN_LISTENER, "--topic", topic, "__name:=run_listener"), name="run_listener")
    stock_listener = spawn(stock(PLAIN_LISTENER, "--topic", topic, "__name:=stock_plain_listener"),
                           name="stock_plain_listener")
    # a stock talker the micros_rt listener must hear over TCPROS
    stock_talker = spawn(stock(PLAIN_TALKER, "--topic", "/stock_chatter", "--rate", "20",
                               "__name:=stock_plain_talker"), name="stock_plain_talker")
    from_stock = spawn(run(PLAIN_LISTENER, "--topic", "/stock_chatter", "--tcp-nodelay", "__name:=run_from_stock"),
                       name="run_from_stock")
    for peer in (listener, stock_listener, from_stock):
        assert peer.wait_for("ready", 60)["is_rospy_subscriber"] is True
    talker = spawn(run(PLAIN_TALKER, "--topic", topic, "--rate", "300", "--queue-size", "1000",
                       "--wait-subscribers", "2", "__name:=run_talker"), name="run_talker")
    assert talker.wait_for("ready", 60)["is_rospy_publisher"] is True

    # 1,000 messages, in order, over shared memory between the two micros-rt run scripts (one host); TCPROS to the
    # stock one
    listener.wait_for_count("recv", 1000, timeout=60)
    stock_listener.wait_for_count("recv", 1000, timeout=60)
    assert received(listener)[:1000] == [f"hello {i}" for i in range(1000)]
    assert set(transports(listener)) == {"SHM"}
    assert received(stock_listener)[:1000] == [f"hello {i}" for i in range(1000)]
    assert set(transports(stock_listener)) == {"TCPROS"}
    # the connection header names the publishing node on both transports, as rospy's does
    assert {e["callerid"] for e in listener.events("recv") + stock_listener.events("recv")} == {"/run_talker"}

    # the kernel's socket table: no TCP link between the two micros-rt run processes, one to the stock node
    dds_pair = data_links_between(ros_master, ("/run_talker", talker.pid), ("/run_listener", listener.pid))
    stock_pair = tcp_links_between(stock_listener.pid, talker.pid)
    print(f"ss: run_talker(pid {talker.pid}) <-> run_listener(pid {listener.pid}): {dds_pair}; "
          f"stock_plain_listener(pid {stock_listener.pid}) -> run_talker: {stock_pair}")
    assert dds_pair == []
    assert stock_pair, "the stock listener should hold a TCPROS socket to the talker"

    # what the ROS graph says: getBusInfo and rosnode info
    talker_links = links_of(ros_master, "/run_talker", topic)
    print("getBusInfo /run_talker:", talker_links)
    assert talker_links == {"/run_listener": "SHM", "/stock_plain_listener": "TCPROS"}
    info = harness.rosnode(ros_master, "info", "/run_listener", timeout=30).stdout
    assert "/run_talker" in info and "SHM" in info, info

    # rostopic echo (stock, TCPROS) hears the micros-rt run talker
    echo = harness.rostopic(ros_master, "echo", "-n", "3", topic, timeout=30).stdout
    assert echo.count("data: \"hello") == 3, echo

    # the micros-rt run listener hears the stock talker over TCPROS (tcp_nodelay=True asked for)
    from_stock.wait_for_count("recv", 5, timeout=30)
    assert set(transports(from_stock)) == {"TCPROS"}
    assert set(links_of(ros_master, "/run_from_stock", "/stock_chatter").values()) == {"TCPROS"}
    assert stock_talker.alive()


def test_profile_gives_an_unmodified_subscriber_a_time_filter(ros_master: harness.RosMaster,
                                                              spawn: harness.Spawner, tmp_path: Path) -> None:
    profile = tmp_path / "qos.yaml"
    profile.write_text("subscribers:\n  /run_filtered: {time_filter_duration: 1.0}\n")
    filtered = spawn(run(PLAIN_LISTENER, "--topic", "/run_filtered", "__name:=run_filtered", profile=profile),
                     name="run_filtered")
    unfiltered = spawn(run(PLAIN_LISTENER, "--topic", "/run_filtered", "__name:=run_unfiltered"),
                       name="run_unfiltered")
    tcp_only = spawn(run(PLAIN_LISTENER, "--topic", "/run_filtered", "__name:=run_tcp_only", hints="tcp"),
                     name="run_tcp_only")
    for peer in (filtered, unfiltered, tcp_only):
        peer.wait_for("ready", 60)
    talker = spawn(run(PLAIN_TALKER, "--topic", "/run_filtered", "--rate", "50", "--count", "200",
                       "--wait-subscribers", "3"), name="run_filtered_talker")
    assert talker.wait(60) == 0
    assert talker.events("done")[0]["sent"] == 200
    unfiltered.wait_for_count("recv", 200, timeout=30)
    filtered.stop()
    n_filtered, n_all = len(received(filtered)), len(received(unfiltered))
    print(f"time filter 1.0 s from the profile: {n_filtered} of {n_all} messages (200 sent at 50 Hz, ~4 s)")
    assert n_all == 200
    assert set(transports(filtered)) == {"SHM"}
    assert 2 <= n_filtered <= 7, n_filtered  # ~4 s of data at one message per second
    # --hints tcp: that script's subscription never uses DDS, even from a micros_rt publisher
    tcp_only.wait_for_count("recv", 200, timeout=30)
    assert set(transports(tcp_only)) == {"TCPROS"}


def test_services_params_timers_and_wait_for_message_under_run(ros_master: harness.RosMaster,
                                                              spawn: harness.Spawner) -> None:
    talker = spawn(run(PLAIN_TALKER, "--topic", "/run_wfm", "--rate", "20", "__name:=run_wfm_talker"),
                   name="run_wfm_talker")
    talker.wait_for("ready", 60)
    probe = spawn(run(PLAIN_PROBE, "services", "--topic", "/run_wfm", "__name:=run_probe"), name="run_probe")
    assert probe.wait(60) == 0, probe.stderr_tail()
    events = {e["event"]: e for e in probe.events()}
    print("probe:", json.dumps({k: {f: v for f, v in e.items() if f != "_rx"} for k, e in events.items()}))
    params = events["params"]
    assert params["private"] == 42 and params["resolved"] == "/run_probe/answer" and params["has"] is True
    assert params["glob"] == {"a": [1, 2], "b": "x"} and params["default"] == "fallback"
    assert events["param_deleted"]["has"] is False
    assert events["service"] == {**events["service"], "success": True, "message": "triggered 1"}
    assert events["timer"]["ticks"] >= 3
    assert abs(events["time"]["get_time"] - events["time"]["wall"]) < 5.0
    assert events["wait_for_message"]["data"].startswith("hello ")
    assert events["wait_for_message"]["transport"] == "SHM"
    assert events["wait_timeout"]["raised"] is True
    assert events["shutdown"] == {**events["shutdown"], "is_shutdown": True, "hooks": ["called"]}
    assert "plain_probe says hello on /rosout" in "\n".join(e.get("line", "") for e in probe.events("_raw"))
    # wait_for_message's subscriber was unregistered again: the talker keeps no link to the probe
    harness.wait_until(lambda: "/run_probe" not in links_of(ros_master, "/run_wfm_talker", "/run_wfm"), 20,
                       message="the probe's links to go")


def test_an_unmodified_rospy_service_and_proxy_reach_ros2_under_run(ros_master: harness.RosMaster,
                                                                    spawn: harness.Spawner) -> None:
    # an rclpy server, called by rospy.ServiceProxy in an unmodified script; the script's rospy.Service, called by
    # an rclpy client (both ROS 2 peers in their own venv and process)
    server = spawn([harness.ROS2_PYTHON, ROS2_SERVICE_PEER, "serve", "--services",
                    json.dumps([{"name": "/run_r2/flag", "type": "std_srvs/srv/SetBool"}])], name="rclpy_server")
    server.wait_for("ready", 60)
    serving = spawn(run(PLAIN_SERVICE, "serve", "/run_plain/flag", "__name:=run_plain_server"), name="plain_server")
    serving.wait_for("ready", 60)
    caller = spawn(run(PLAIN_SERVICE, "call", "/run_r2/flag", "--count", "3", "__name:=run_plain_caller"),
                   name="plain_caller")
    client = spawn([harness.ROS2_PYTHON, ROS2_SERVICE_PEER, "call", "--plan", json.dumps([
        {"label": "plain", "name": "/run_plain/flag", "type": "std_srvs/srv/SetBool", "args": {"data": True},
         "wait": 30, "timeout": 10}])], name="rclpy_client")
    assert caller.wait(90) == 0, caller.stderr_tail()
    assert [(e["success"], e["message"]) for e in caller.events("response")] == [
        (True, "rclpy /run_r2/flag got True"), (False, "rclpy /run_r2/flag got False"),
        (True, "rclpy /run_r2/flag got True")], caller.events()[-6:]
    assert caller.events("done")[0]["classes"] == ["micros_rt.drop_in"]
    client.wait_for("done", 90)
    answer = [e for e in client.events("response") if e.get("label") == "plain"]
    assert answer and answer[0]["fields"] == {"success": True, "message": "plain /run_plain/flag got True"}, \
        client.events()[-6:]
    # a stock ROS 1 client still reaches the same rospy.Service over TCPROS
    cp = subprocess.run([harness.STOCK_PYTHON, "/usr/bin/rosservice", "call", "/run_plain/flag", "data: false"],
                        env=ros_master.env, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    assert cp.returncode == 0 and "plain /run_plain/flag got False" in cp.stdout, (cp.stdout, cp.stderr)


def test_an_unmodified_actionlib_client_reaches_a_ros2_action_server_under_run(ros_master: harness.RosMaster,
                                                                              spawn: harness.Spawner) -> None:
    # an rclpy action server (test_msgs/action/Fibonacci, its own venv and process); no ROS 1 server of the name
    name = "/run_r2/fib"
    server = spawn([harness.ROS2_PYTHON, ROS2_ACTION_PEER, "serve", "--actions", json.dumps([{"name": name}])],
                   name="rclpy_action_server")
    server.wait_for("ready", 60)
    # the unmodified SimpleActionClient script as a stock node finds no server of the name: actionlib's
    # wait_for_server times out (first: once the micros-rt run script below offers the action, the master has it)
    plain = spawn(stock(PLAIN_ACTION_CLIENT, name, "--wait", "3", "__name:=stock_plain_action_client"),
                  name="stock_plain_action_client")
    assert plain.wait(60) == 1, plain.stderr_tail()
    assert plain.events("unavailable") and not plain.events("active"), plain.events()
    # the same script under micros-rt run reaches the rclpy server
    # under what users get (shared memory, ROS 2 visibility auto): the script's own links to the action's topics
    # are shared-memory links, whose callerid_pub actionlib reads
    client = spawn(run(PLAIN_ACTION_CLIENT, name, "--order", "20", "__name:=run_plain_action_client"),
                   env=user_defaults(ros_master.env), name="run_plain_action_client")
    assert client.wait(60) == 0, client.stderr_tail()
    print("micros-rt run actionlib client:", json.dumps([{k: v for k, v in e.items() if k != "_rx"}
                                                         for e in client.events() if e["event"] != "_raw"]))
    assert [e["label"] for e in client.events("active")] == ["fib", "cancel"], client.events()[-6:]
    results = {e["label"]: e for e in client.events("result")}
    fib = results["fib"]   # goal accepted, every feedback message in order, the result
    assert (fib["status_name"], fib["feedback"], fib["feedback_in_order"], fib["sequence_ok"], fib["text"]) == \
        ("SUCCEEDED", 20, True, True, "succeeded on the ROS 2 action server"), fib
    cancel = results["cancel"]   # cancel_goal() after 5 feedback messages: the rclpy server cancels
    assert (cancel["status_name"], cancel["text"]) == ("PREEMPTED", "canceled on the ROS 2 action server"), cancel
    assert cancel["feedback_in_order"] and 5 <= cancel["feedback"] < 5000, cancel
    # the rclpy server is the one that ran both goals and got the cancel
    assert [(e["name"], e["order"]) for e in server.events("goal")] == [(name, 20), (name, 5000)], server.events()
    assert server.wait_for(lambda e: e.get("event") == "finished" and e["status"] == "CANCELED", 10)
    assert len(server.events("cancel_received")) == 1, server.events()
    assert "Traceback" not in client.stderr_tail(200), client.stderr_tail(200)   # a clean exit, offer and all


@pytest.mark.parametrize("hints", [None, "tcp", "client_tcp"])
def test_an_unmodified_actionlib_client_and_server_both_under_run(ros_master: harness.RosMaster,
                                                                  spawn: harness.Spawner, hints: Optional[str]) -> None:
    """actionlib's client is ready only when its result and feedback connections name the server's node
    (``callerid_pub``): on shared-memory links it once saw the publisher's URI and waited forever. Its first goal is
    sent once its goal publisher ``has_connection`` to the server: a shared-memory link counted before the server's
    subscriber had attached, and the goal was lost (PENDING until the timeout), also with ``--hints tcp`` on the
    client only (the server's goal subscriber still offers shared memory). ``tcp``: every link TCPROS."""
    env = user_defaults(ros_master.env)
    name = f"/run_both{'_' + hints if hints else ''}/fib"
    server = spawn(run(ROS1_ACTION_PEER, "serve", "--name", name, "--period", "0.01",
                       hints="tcp" if hints == "tcp" else None), env=env, name="run_action_server")
    server.wait_for("ready", 60)
    client = spawn(run(PLAIN_ACTION_CLIENT, name, "--order", "20", "--wait", "20", "__name:=run_both_client",
                       hints="tcp" if hints else None), env=env, name="run_action_client")
    assert client.wait(90) == 0, (client.events()[-6:], client.stderr_tail())
    available = client.wait_for("available", 1)
    print(f"\nactionlib client under micros-rt run (hints {hints}): server available after "
          f"{available['elapsed']:.2f} s")
    assert available["elapsed"] < 5.0, available
    results = {e["label"]: e for e in client.events("result")}
    fib = results["fib"]
    # every feedback message from the first the client could take to the last, none lost or reordered between: stock
    # actionlib's client drops one that arrives before send_goal() has stored the goal's handle, which the server's
    # first (sent at once) can do on a loaded machine (seen 1 in ~10 loaded runs: 19 of 20, from 1)
    assert (fib["status_name"], fib["feedback_unbroken"], fib["feedback_first"] + fib["feedback"], fib["sequence_ok"]) \
        == ("SUCCEEDED", True, 20, True), (fib, server.events()[-4:])
    assert fib["feedback_first"] <= 1, fib
    cancel = results["cancel"]
    assert cancel["status_name"] == "PREEMPTED" and cancel["feedback_in_order"] and cancel["feedback"] >= 5, cancel
    assert server.wait_for(lambda e: e.get("event") == "finished" and e["status"] == "PREEMPTED", 10)


def _run_cli(argv: List[str], env: Dict[str, str], cwd: Optional[Path] = None) -> "subprocess.CompletedProcess[str]":
    return subprocess.run(argv, env=env, cwd=str(cwd or harness.REPO_ROOT), stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, timeout=60)


def _event(cp: "subprocess.CompletedProcess[str]", kind: str) -> Dict[str, Any]:
    for line in cp.stdout.splitlines():
        if line.startswith("{") and json.loads(line).get("event") == kind:
            return dict(json.loads(line))
    raise AssertionError(f"no {kind!r} event in stdout:\n{cp.stdout}\nstderr:\n{cp.stderr}")


def test_argv_name_path_remappings_and_exit_code_are_the_scripts(ros_master: harness.RosMaster) -> None:
    env = ros_master.env
    args = ["argv", "--exit", "3", "-h", "--profile", "x", "chatter:=/remapped", "__name:=probe_argv", "__ns:=/ns1",
            "_answer:=7"]
    cp = _run_cli(run(PLAIN_PROBE, *args), env)
    assert cp.returncode == 3, cp.stderr
    got = _event(cp, "argv")
    print("micros-rt run argv:", got)
    assert got["argv"] == [PLAIN_PROBE, *args]  # -h and --profile after SCRIPT are the script's
    assert got["myargv"] == [PLAIN_PROBE, "argv", "--exit", "3", "-h", "--profile", "x"]
    assert got["name"] == "__main__"
    assert got["path0"] == str(harness.PEERS_DIR) and got["file"] == PLAIN_PROBE
    assert got["node"] == "/ns1/probe_argv" and got["namespace"] == "/ns1/" and got["chatter"] == "/remapped"
    assert got["private_param"] == 7

    # the same through python -m micros_rt, with a relative script path (python makes __file__ absolute)
    cp = _run_cli([harness.MICROS_RT_PYTHON, "-m", "micros_rt", "run", "peers/plain_probe.py", "argv", "--exit", "0"],
                  env, cwd=harness.TESTS_DIR)
    assert cp.returncode == 0, cp.stderr
    got = _event(cp, "argv")
    assert got["argv"][0] == "peers/plain_probe.py" and got["file"] == PLAIN_PROBE and got["node"] == "/plain_probe"

    # an exception: python's traceback (from the script's frame on) and exit code 1
    cp = _run_cli(run(PLAIN_PROBE, "raise"), env)
    assert cp.returncode == 1
    assert cp.stderr.startswith("Traceback (most recent call last):\n  File \"" + PLAIN_PROBE), cp.stderr
    assert cp.stderr.rstrip().endswith("RuntimeError: boom from the script"), cp.stderr
    # no frame of micros_rt's own code (wherever the clone is: its directory may itself be named micros_rt)
    package = str(harness.REPO_ROOT / "micros_rt") + os.sep
    frames = [line for line in cp.stderr.splitlines() if line.startswith('  File "')]
    assert frames and not any(package in line or "micros_rt." in line for line in frames), cp.stderr
    stock_cp = _run_cli(stock(PLAIN_PROBE, "raise"), env)
    assert (stock_cp.returncode, stock_cp.stderr) == (cp.returncode, cp.stderr)

    # sys.exit("message"): the message on stderr, exit code 1, as python does
    cp = _run_cli(run(PLAIN_PROBE, "exit-message"), env)
    assert (cp.returncode, cp.stderr.strip()) == (1, "bye from the script")


def test_user_mistakes_are_one_line_errors(tmp_path: Path) -> None:
    env = harness.child_env()
    not_python = tmp_path / "node.sh"
    not_python.write_text("#!/bin/sh\necho hi\n")
    bad_profile = tmp_path / "bad.yaml"
    bad_profile.write_text("subscribers:\n  /x: {time_filter: 1.0}\n")
    cases = [
        (run(str(tmp_path / "missing.py")), "can't open file"),
        ([MICROS_RT, "run"], "no SCRIPT given"),
        (run(PLAIN_PROBE, "raise", hints="dds,udp"), "unknown protocol 'udp'"),
        (run(str(not_python)), "is not a Python script"),
        (run(PLAIN_PROBE, "raise", profile=bad_profile), "time_filter"),
    ]
    for argv, words in cases:
        cp = _run_cli(argv, env)
        lines = cp.stderr.strip().splitlines()
        assert cp.returncode == 2 and len(lines) == 1 and words in lines[0], (argv, cp.returncode, cp.stderr)
        assert lines[0].startswith("micros-rt run: "), lines
    cp = _run_cli([MICROS_RT, "run", "-h"], env)
    assert cp.returncode == 0 and "SCRIPT [ARGS...]" in cp.stdout and "launch-prefix" in cp.stdout


def test_subscriber_listener_and_headers_under_run(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    announcer = spawn(run(PLAIN_PROBE, "announce", "--topic", "/run_announce", "__name:=run_announcer"),
                      name="run_announcer")
    announcer.wait_for("ready", 60)
    dds_listener = spawn(run(PLAIN_LISTENER, "--topic", "/run_announce", "__name:=run_welcomed"), name="run_welcomed")
    tcp_listener = spawn([harness.STOCK_PYTHON, str(harness.STOCK_LISTENER), "--topic", "/run_announce",
                          "--node-name", "stock_welcomed"], name="stock_welcomed")
    # peer_subscribe for both subscribers: the TCPROS one (rospy's call) and the DDS one (micros_rt's)
    announcer.wait_for(lambda e: e.get("event") == "peer_subscribe" and e.get("n") == 2, 60)
    welcome_dds = dds_listener.wait_for("recv", 30)
    welcome_tcp = tcp_listener.wait_for("recv", 30)
    print("subscriber_listener:", welcome_dds["data"], welcome_dds["transport"], "/", welcome_tcp["data"],
          welcome_tcp["connection_header"])
    assert welcome_dds["data"].startswith("welcome ") and welcome_dds["transport"] == "SHM"
    assert welcome_tcp["data"].startswith("welcome ")
    assert welcome_tcp["connection_header"]["robot"] == "r2"  # Publisher(headers=...) on the TCPROS link
    links = links_of(ros_master, "/run_announcer", "/run_announce")
    assert links == {"/run_welcomed": "SHM", "/stock_welcomed": "TCPROS"}, links
    # the DDS subscriber leaves: rospy's remove_connection tells the listener
    dds_listener.stop()
    announcer.wait_for("peer_unsubscribe", 30)


def test_second_subscriber_of_a_latched_topic_gets_the_latched_message(ros_master: harness.RosMaster,
                                                                       spawn: harness.Spawner) -> None:
    # one message at start, the next 10 s later: only the latched copy can answer within the probe's 3 s
    latched = ("--latch", "--rate", "0.1")
    dds_talker = spawn(run(PLAIN_TALKER, "--topic", "/run_latched_dds", *latched, "__name:=run_latched_talker"),
                       name="run_latched_talker")
    tcp_talker = spawn(stock(PLAIN_TALKER, "--topic", "/run_latched_tcp", *latched, "__name:=stock_latched_talker"),
                       name="stock_latched_talker")
    dds_talker.wait_for("ready", 60)
    tcp_talker.wait_for("ready", 60)
    probe = spawn(run(PLAIN_PROBE, "latched", "--topics", "/run_latched_dds,/run_latched_tcp",
                      "__name:=run_latched_probe"), name="run_latched_probe")
    assert probe.wait(60) == 0, probe.stderr_tail()
    got = {e["topic"]: (e["data"], e["transport"]) for e in probe.events("latched")}
    print("wait_for_message on subscribed latched topics:", got)
    assert got == {"/run_latched_dds": ("hello 0", "SHM"), "/run_latched_tcp": ("hello 0", "TCPROS")}
