"""Services over MQTT (AimRT's RPC back end): a rospy service of one graph called from another graph through
mosquitto, request/response correlation under concurrent calls, two servers sharing the load, a timeout in
words, and the servers still registered with (and callable in) their own graph."""

from __future__ import annotations

import re
import subprocess
from collections import Counter
from pathlib import Path

import harness
from mqtt_broker import MosquittoBroker, write_params

PEER = str(harness.PEERS_DIR / "mqtt_service_peer.py")
N = 40


def test_service_across_graphs_load_sharing_and_timeout(
        ros_master: harness.RosMaster, fresh_master: harness.RosMaster, spawn: harness.Spawner,
        tmp_path: Path) -> None:
    with MosquittoBroker(tmp_path / "broker") as broker:
        profile = write_params(tmp_path / "profile.yaml", {"mqtt": {"broker": {"host": broker.host,
                                                                              "port": broker.port}}})
        env_a = dict(ros_master.env, MICROS_RT_QOS_PROFILE=str(profile))
        env_b = dict(fresh_master.env, MICROS_RT_QOS_PROFILE=str(profile))
        servers = [spawn([harness.MICROS_RT_PYTHON, PEER, "serve", "--id", sid, "--duration", "90"], env_a,
                         name=f"server{sid}") for sid in ("1", "2")]
        for server in servers:
            server.wait_for("ready", timeout=60)

        # still a ROS service of graph A: registered with its master, callable by stock rosservice
        uri = harness.master_call(ros_master, "lookupService", "/camera/set_camera_info")
        stock = subprocess.run(["/usr/bin/rosservice", "call", "/camera/set_camera_info",
                                "{camera_info: {header: {frame_id: stock}}}"], env=ros_master.env,
                               capture_output=True, text=True, timeout=60)
        assert stock.returncode == 0 and "got stock" in stock.stdout, stock.stderr

        caller = spawn([harness.MICROS_RT_PYTHON, PEER, "call", "--count", str(N), "--threads", "4", "--timeout", "10"],
                       env_b, name="caller")
        caller.wait_for("done", timeout=90)
        replies = caller.events("reply")
        assert not caller.events("error"), caller.events("error")
        assert len(replies) == N
        for r in replies:   # each answer belongs to its own request (msg id correlation under 4 threads)
            assert re.fullmatch(rf"server [12] got {r['frame_id']}", r["status"]), r
        by_server = Counter(r["status"].split()[1] for r in replies)
        assert set(by_server) == {"1", "2"}, by_server         # the shared subscription spreads the load

        lonely = spawn([harness.MICROS_RT_PYTHON, PEER, "call", "--service", "/nobody/here", "--count", "1",
                        "--threads", "1", "--timeout", "1"], env_b, name="lonely")
        lonely.wait_for("done", timeout=60)
        (error,) = lonely.events("error")
        assert "no response within 1 s" in error["text"] and "/nobody/here" in error["text"]
        assert 0.9 <= error["seconds"] < 5.0
        print(f"graph B -> graph A over MQTT: {len(replies)} of {N} calls answered, correlated under 4 threads; "
              f"load: {dict(by_server)}; registered in graph A at {uri}; stock rosservice: "
              f"{stock.stdout.strip().splitlines()[-1]}\ntimeout after {error['seconds']:.2f} s: {error['text']}")
