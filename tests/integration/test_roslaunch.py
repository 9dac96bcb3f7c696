"""roslaunch starts unmodified rospy nodes under micros_rt with ``launch-prefix="micros-rt run"``.

Debian's ``roslaunch`` and a package the test makes in a tmp dir on ROS_PACKAGE_PATH (package.xml, the
plain talker/listener scripts as executables, a launch file with a namespace, <remap>, <param> and
respawn). The test's own master is used (roslaunch starts none when one answers at ROS_MASTER_URI);
logs go to the master's tmp ROS_HOME/ROS_LOG_DIR.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
from pathlib import Path
from typing import Any, Dict, List, Tuple

import pytest

import harness
from helpers import bus_info, stock_listener, tcp_links_between
from test_relay import robots  # noqa: F401  (the two-master fixture)

pytestmark = pytest.mark.env(**harness.DDS_BETWEEN_NODES)

VENV_BIN = harness.REPO_ROOT / ".venv" / "bin"
ROSLAUNCH = "/usr/bin/roslaunch"

PACKAGE_XML = """<?xml version="1.0"?>
<package format="2">
  <name>run_demo</name>
  <version>0.0.1</version>
  <description>Plain rospy nodes launched under micros-rt run</description>
  <maintainer email="nobody@example.com">nobody</maintainer>
  <license>BSD</license>
  <buildtool_depend>catkin</buildtool_depend>
</package>
"""

# the talker through PATH, the listener through the absolute path: the two documented forms
LAUNCH = """<launch>
  <group ns="robot">
    <node pkg="run_demo" type="talker.py" name="talker" args="--rate 20" launch-prefix="micros-rt run"
          respawn="true" output="screen">
      <param name="greeting" value="hola"/>
      <remap from="chatter" to="speech"/>
    </node>
    <node pkg="run_demo" type="listener.py" name="listener" launch-prefix="{micros_rt} run" output="screen">
      <remap from="chatter" to="speech"/>
    </node>
  </group>
</launch>
"""


def make_package(root: Path) -> Path:
    pkg = root / "run_demo"
    (pkg / "scripts").mkdir(parents=True)
    (pkg / "launch").mkdir()
    (pkg / "package.xml").write_text(PACKAGE_XML)
    for name in ("talker", "listener"):
        script = pkg / "scripts" / f"{name}.py"
        shutil.copy(harness.PEERS_DIR / f"plain_{name}.py", script)
        script.chmod(0o755)
    (pkg / "launch" / "pair.launch").write_text(LAUNCH.format(micros_rt=VENV_BIN / "micros-rt"))
    return pkg


def is_ready(node: str) -> Any:
    return lambda e: e.get("event") == "ready" and e.get("node") == node


def test_launch_prefix_runs_two_plain_nodes_over_dds_with_remap_param_namespace_respawn(
        fresh_master: harness.RosMaster, spawn: harness.Spawner, tmp_path: Path) -> None:
    make_package(tmp_path / "ws")
    env: Dict[str, str] = dict(fresh_master.env)
    env["ROS_PACKAGE_PATH"] = str(tmp_path / "ws")
    env["PATH"] = f"{VENV_BIN}{os.pathsep}{env.get('PATH', '/usr/bin:/bin')}"
    launch = spawn([harness.STOCK_PYTHON, ROSLAUNCH, "run_demo", "pair.launch"], env=env, name="roslaunch")

    talker = launch.wait_for(is_ready("/robot/talker"), 60)
    listener = launch.wait_for(is_ready("/robot/listener"), 60)
    assert talker["topic"] == listener["topic"] == "/robot/speech"  # namespace + <remap>
    assert talker["greeting"] == "hola"  # <param> (private ~greeting)
    assert harness.master_call(fresh_master, "getParam", "/robot/talker/greeting") == "hola"

    def heard(start: int = 0) -> Any:
        return launch.wait_for(lambda e: e.get("event") == "recv" and e.get("callerid") == "/robot/talker", 60,
                               start=start)

    def sources() -> Dict[str, str]:  # the listener's links: publisher URI -> transport
        return {str(c[1]): str(c[3]) for c in bus_info(fresh_master, "/robot/listener") if c[4] == "/robot/speech"}

    first = heard()
    assert first["transport"] == "DDS" and first["data"].startswith("hola ")
    links = {str(c[1]): str(c[3]) for c in bus_info(fresh_master, "/robot/talker") if c[4] == "/robot/speech"}
    sockets = tcp_links_between(talker["pid"], listener["pid"]) + tcp_links_between(listener["pid"], talker["pid"])
    print(f"launched: talker pid {talker['pid']}, listener pid {listener['pid']}, getBusInfo {links}, "
          f"TCP links between them {sockets}")
    assert links == {"/robot/listener": "DDS"}
    assert sockets == []

    # respawn: kill the talker, roslaunch starts it again, the listener hears the new one over DDS
    mark = len(launch.events())
    os.kill(talker["pid"], signal.SIGKILL)
    again = launch.wait_for(lambda e: is_ready("/robot/talker")(e) and e.get("pid") != talker["pid"], 60, start=mark)
    resumed = heard(start=launch.events().index(again))
    assert resumed["transport"] == "DDS" and resumed["data"].startswith("hola ")
    harness.wait_until(lambda: sources() == {again["uri"]: "DDS"}, 30, message="the listener's only link to be "
                       f"the respawned talker's, over DDS (now {sources()})")
    sockets = tcp_links_between(again["pid"], listener["pid"]) + tcp_links_between(listener["pid"], again["pid"])
    links = {str(c[1]): str(c[3]) for c in bus_info(fresh_master, "/robot/talker") if c[4] == "/robot/speech"}
    print(f"respawned: talker pid {again['pid']} (was {talker['pid']}), getBusInfo {links}, TCP links {sockets}")
    assert links == {"/robot/listener": "DDS"} and sockets == []
    starts = [e["line"] for e in launch.events("_raw") if "robot/talker" in e["line"] and "started with pid" in e["line"]]
    assert len(starts) == 2, starts  # roslaunch's own account of the respawn

    # roslaunch's SIGINT stops both nodes (each prints its summary line on rospy's shutdown)
    launch.stop(timeout=20)
    assert launch.wait_for(lambda e: e.get("event") == "done" and "received" in e, 5)["received"] > 0


def test_launch_example_runs_with_profile_and_absolute_prefix(fresh_master: harness.RosMaster,
                                                              spawn: harness.Spawner) -> None:
    """examples/launch/micros_rt_run_demo as documented: micros-rt by absolute path, a QoS profile."""
    env: Dict[str, str] = dict(fresh_master.env)
    env["ROS_PACKAGE_PATH"] = str(harness.REPO_ROOT / "examples" / "launch")
    launch = spawn([harness.STOCK_PYTHON, ROSLAUNCH, "micros_rt_run_demo", "talker_listener.launch",
                    f"micros_rt:={VENV_BIN / 'micros-rt'}"], env=env, name="roslaunch_example")
    heard = re.compile(r"/demo/listener heard \[hello world (\d+)\] via (\w+)")

    def lines() -> List[Tuple[int, str]]:
        found = (heard.search(e["line"]) for e in launch.events("_raw"))
        return [(int(m.group(1)), m.group(2)) for m in found if m]

    got = harness.wait_until(lambda: len(lines()) >= 4 and lines(), 60, interval=0.2,
                             message="four 'heard ... via' lines from the example's listener")
    print("example listener:", got)
    assert {t for _, t in got} == {"DDS"}
    gaps = [b - a for (a, _), (b, _) in zip(got, got[1:])]
    assert min(gaps) >= 5, gaps  # 20 Hz through the profile's 0.5 s time filter: ~10 apart
    echo = harness.rostopic(fresh_master, "echo", "-n", "1", "/demo/speech", timeout=30).stdout
    assert "hello world" in echo  # a stock subscriber gets TCPROS from the same talker


def test_a_relay_in_a_launch_file_sends_the_robots_topic_to_another_graph(
        robots: Tuple[harness.RosMaster, harness.RosMaster], spawn: harness.Spawner, tmp_path: Path) -> None:
    """examples/launch/micros_rt_run_demo/launch/relay.launch in robot A's graph (the talker under micros-rt run,
    the relay as a launch file node with respawn), a relay and a stock listener in robot B's graph."""
    a, b = robots
    env: Dict[str, str] = dict(a.env)
    env["ROS_PACKAGE_PATH"] = str(harness.REPO_ROOT / "examples" / "launch")
    launch = spawn([harness.STOCK_PYTHON, ROSLAUNCH, "micros_rt_run_demo", "relay.launch",
                    f"micros_rt:={VENV_BIN / 'micros-rt'}"], env=env, name="roslaunch_relay")
    (tmp_path / "b.yaml").write_text("graph: robot_b\nimport:\n  /robot_a/demo/speech: {}\n")
    spawn([str(VENV_BIN / "micros-rt"), "relay", "--config", str(tmp_path / "b.yaml")], env=b.env, name="relay_b")
    listener = spawn(stock_listener("--topic", "/robot_a/demo/speech", "--count", 6, "--duration", 90), env=b.env)
    got = listener.wait_for_count("recv", 6, timeout=90)
    seqs = [int(e["data"].split()[-1]) for e in got]
    print(f"robot B heard A's launched talker through the launched relay: {seqs}")
    assert all(e["data"].startswith("hello world ") for e in got), got[:2]
    gaps = [y - x for x, y in zip(seqs, seqs[1:])]
    assert min(gaps) >= 2, seqs       # 20 Hz in A, at most 5 Hz on the link (config/relay.yaml's max_rate)
    stats = launch.wait_for(lambda e: e.get("event") == "stats" and bool(e.get("exports")), 30)
    assert stats["exports"][0]["topic"] == "/demo/speech" and stats["exports"][0]["as"] == "/robot_a/demo/speech"
    subscribers = dict((t, n) for t, n in harness.master_call(a, "getSystemState")[1])
    assert "/relay_robot_a" in subscribers["/demo/speech"], subscribers  # the launch file's node name
