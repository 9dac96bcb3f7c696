"""Shared memory (SHM) between micros_rt nodes of one host, beside TCPROS and DDS on the same topic.

Real processes: a rosmaster, micros_rt nodes (SHM on: the harness turns it off for the rest of the suite),
a stock rospy listener, an rclpy listener in its own venv. Every message is counted at every subscriber.
"""

from __future__ import annotations

import os
import pwd
import re
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Dict, List

import pytest

import harness
from helpers import mrt, received, stock_listener, transports

pytestmark = pytest.mark.integration

T = 60.0


def shm_env(master: harness.RosMaster, mode: str = "default") -> Dict[str, str]:
    """SHM on; the delivery thread waits on its links itself (iceoryx2's wait set). ``default``: what users get
    (ROS 2 visibility auto); ``beside_dds``: each node has DDS too from its start (visibility on, as once a ROS 2
    node is on the domain), whose readers wake that thread from Cyclone's thread; ``alone``: no DDS."""
    env = {**master.env, "MICROS_RT_DISABLE_SHM": "0"}
    if mode == "alone":
        env["MICROS_RT_DISABLE_DDS"] = "1"
    elif mode == "beside_dds":
        env["MICROS_RT_ROS2"] = "on"
    return env


@pytest.fixture(params=["beside_dds", "alone"])
def mode(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def iox_entries() -> List[str]:
    return sorted(n for n in os.listdir("/dev/shm") if n.startswith("iox2_"))


def test_shm_tcpros_and_dds_on_one_topic_each_message_once(ros_master: harness.RosMaster,
                                                          spawn: harness.Spawner, tmp_path: Path) -> None:
    env = shm_env(ros_master)
    topic = "/shm/mixed"
    n = 100
    shm_listener = spawn(mrt("listen", "--topic", topic, "--duration", T), env, name="mrt_listener")
    stock = spawn(stock_listener("--topic", topic, "--duration", T), name="stock_listener")
    ros2 = spawn(harness.ros2_peer_argv("listen", "--topic", topic, "--count", str(n), "--duration", str(T)),
                 name="rclpy_listener")
    for peer in (shm_listener, stock, ros2):
        peer.wait_for("ready", T)
    # the counted messages go once the rclpy reader has matched the talker's writer too (its graph counts it; the
    # writer's own count is one side of the match): volatile, a message before that would not reach it
    start = tmp_path / "start"
    talker = spawn(mrt("talk", "--topic", topic, "--count", n, "--rate", 50, "--wait-subscribers", 2,
                       "--wait-dds-readers", 1, "--start-file", start, "--start-delay", 0.3, "--linger", T,
                       "--queue-size", 0), env, name="mrt_talker")
    talker.wait_for("dds_matched", T)
    ros2.wait_for(lambda e: e.get("event") == "matched" and e.get("n", 0) >= 1, T)
    start.touch()
    want = [f"hello {i}" for i in range(n)]
    shm_listener.wait_for_count("recv", n, T)
    stock.wait_for_count("recv", n, T)
    ros2.wait_for_count("recv", n, T)
    talker.wait_for(lambda e: e.get("event") == "sent" and e.get("seq") == n - 1, T)
    time.sleep(0.5)  # nothing may arrive twice: give a duplicate the time to show up
    assert received(shm_listener) == want
    assert set(transports(shm_listener)) == {"SHM"}
    assert [e["data"] for e in stock.events("recv")] == want
    assert sorted(e["data"] for e in ros2.events("recv")) == sorted(want)
    # the tools show the link as what it is
    info = subprocess.run([str(harness.REPO_ROOT / ".venv" / "bin" / "micros-rt"), "topic", "info", topic], env=env,
                          capture_output=True, text=True, timeout=90)
    assert info.returncode == 0, info.stderr
    assert re.search(r"/mrt_\w+ -> /mrt_\w+: SHM", info.stdout), info.stdout
    assert re.search(r"-> /stock_listener\w*: TCPROS", info.stdout), info.stdout


def test_ctrl_c_stops_a_shm_node_at_once_while_its_peer_runs(ros_master: harness.RosMaster,
                                                            spawn: harness.Spawner) -> None:
    # iceoryx2's wait set took SIGINT and SIGTERM for itself: a listener whose delivery thread waited on it ran
    # on after Ctrl-C until SIGKILL (every test_shm teardown took 10 s), which left its shared memory behind
    env = shm_env(ros_master)
    listener = spawn(mrt("listen", "--topic", "/shm/ctrl_c", "--duration", T), env, name="ctrl_c_listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", "/shm/ctrl_c", "--count", 100000, "--rate", 50, "--linger", T), env)
    listener.wait_for_count("recv", 10, T)
    assert set(transports(listener)) == {"SHM"}
    t0 = time.monotonic()
    listener.proc.send_signal(signal.SIGINT)
    listener.proc.wait(T)
    stopped = time.monotonic() - t0
    print(f"SHM listener stopped {stopped:.2f} s after SIGINT, exit code {listener.proc.returncode}")
    assert listener.proc.returncode == 0 and stopped < 5.0, (listener.proc.returncode, stopped)
    assert talker.alive()  # and its publisher goes on


def test_order_by_sending_time_on_shm(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    # two publishers, one whose clock is 0.3 s behind: before the core enforced ordered_by_sending_timestamp
    # (the catalogue's SOURCE_ORDER), only Cyclone ordered, and a shared-memory link delivered every "late"
    env = shm_env(ros_master)
    topic = "/shm/order"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", T, "--queue-size", "1000",
                         qos={"ordered_by_sending_timestamp": True}), env, name="order_listener")
    listener.wait_for("ready", T)
    # "now" sends for 10 s: "late"'s start-up (seconds on a loaded machine) and its 2 s of samples fall inside that
    now = spawn(mrt("talk", "--topic", topic, "--count", "200", "--rate", "20", "--prefix", "now",
                    "--node-name", "talker_now", "--wait-subscribers", "1", "--linger", "2"), env)
    now.wait_for(lambda e: e.get("event") == "sent" and e["seq"] == 5, T)
    late = spawn(mrt("talk", "--topic", topic, "--count", "40", "--rate", "20", "--prefix", "late",
                     "--node-name", "talker_late", "--wait-subscribers", "1", "--linger", "1",
                     "--clock-offset", "-0.3"), env)
    late.wait_for("done", T)
    now.wait_for("done", T)
    # every message reached the subscription (received counts the dropped ones too); before an SHM offer said
    # which channel it held, the listener's link to "now" was made anew when "late" came and went, and a message
    # in the old channel was lost, counted nowhere
    try:
        stats = listener.wait_for(lambda e: e.get("event") == "status" and e["statistics"]["received"] >= 240,
                                  T)["statistics"]
    finally:
        got = received(listener)
        print("never arrived:", sorted(set(f"now {i}" for i in range(200)) - set(got)))
    n_now, n_late = sum(1 for x in got if x.startswith("now")), sum(1 for x in got if x.startswith("late"))
    assert set(transports(listener)) == {"SHM"}
    print(f"order by source on SHM: now={n_now}/200 late={n_late}/40, statistics {stats}")
    assert n_now == 200, n_now
    assert n_late <= 3, got  # only while "now" is silent could one slip through
    assert stats["dropped_out_of_order"] == 40 - n_late, stats  # every drop counted


def test_a_killed_publisher_is_noticed_and_its_restart_reconnects_over_shm(ros_master: harness.RosMaster,
                                                                         spawn: harness.Spawner, mode: str) -> None:
    env = shm_env(ros_master, mode)
    topic = "/shm/restart"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", T), env, name="mrt_listener")
    listener.wait_for("ready", T)
    first = spawn(mrt("talk", "--topic", topic, "--node-name", "shm_talker", "--count", 100000, "--rate", 50,
                      "--prefix", "first"), env, name="first_talker")
    listener.wait_for(lambda e: e.get("event") == "recv" and e.get("transport") == "SHM", T)
    attached = iox_entries()
    first.proc.kill()
    killed = time.monotonic()
    start = len(listener.events())
    # the listener drops the dead link within about 2 s (its status lists the connections it has, every 0.5 s; the
    # link is looked at every second): 4 s leaves a loaded machine room, and a link never dropped still fails
    listener.wait_for(lambda e: e.get("event") == "status" and not e.get("transports"), T, start=start)
    noticed = time.monotonic() - killed
    assert noticed < 4.0, f"the dead publisher was noticed after {noticed:.1f} s"
    start = len(listener.events())
    second = spawn(mrt("talk", "--topic", topic, "--node-name", "shm_talker", "--count", 100000, "--rate", 50,
                       "--prefix", "second"), env, name="second_talker")
    got = listener.wait_for(lambda e: e.get("event") == "recv" and str(e.get("data", "")).startswith("second"),
                            T, start=start)
    assert got["transport"] == "SHM"
    # what the killed process had in /dev/shm was reclaimed: the restart does not add a second set of files
    assert len(iox_entries()) <= len(attached), (attached, iox_entries())
    second.stop()


def test_latched_message_reaches_a_late_shm_subscriber(ros_master: harness.RosMaster,
                                                        spawn: harness.Spawner) -> None:
    env = shm_env(ros_master)
    topic = "/shm/latched"
    talker = spawn(mrt("talk", "--topic", topic, "--count", 3, "--rate", 50, "--latch", "--linger", T), env,
                   name="latched_talker")
    talker.wait_for(lambda e: e.get("event") == "sent" and e["seq"] == 2, T)
    listener = spawn(mrt("listen", "--topic", topic, "--exit-after", 1, "--duration", T), env, name="late")
    listener.wait_for("ready", T)
    t0 = time.monotonic()
    got = listener.wait_for("recv", T)
    assert got["data"] == "hello 2" and got["transport"] == "SHM"
    assert time.monotonic() - t0 < 5.0  # the latched replay, not a later publish (the talker sent its last long ago)


def test_lossless_burst_to_a_slow_shm_subscriber_loses_nothing(ros_master: harness.RosMaster,
                                                               spawn: harness.Spawner) -> None:
    env = shm_env(ros_master)
    topic = "/shm/lossless"
    n = 3000
    listener = spawn(mrt("listen", "--topic", topic, "--queue-size", 0, "--exit-after", n, "--duration", T,
                         "--callback-sleep", 0.0002), env, name="slow_listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", n, "--rate", 0, "--queue-size", 0,
                       "--wait-subscribers", 1, "--linger", 0.5), env, name="burst_talker")
    listener.wait_for_count("recv", n, T)
    done = listener.wait_for("done", T)
    assert received(listener) == [f"hello {i}" for i in range(n)]
    assert set(transports(listener)) == {"SHM"}
    assert done["statistics"]["dropped_queue_full"] == 0
    talker.wait_for("done", T)


def test_keep_last_drops_are_counted_on_shm(ros_master: harness.RosMaster, spawn: harness.Spawner) -> None:
    env = shm_env(ros_master)
    topic = "/shm/keep_last"
    n = 2000
    listener = spawn(mrt("listen", "--topic", topic, "--queue-size", 1, "--duration", 8,
                         "--callback-sleep", 0.002), env, name="slow_listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", n, "--rate", 0, "--queue-size", 1,
                       "--wait-subscribers", 1, "--linger", 0.5), env, name="burst_talker")
    talker.wait_for("done", T)
    done = listener.wait_for("done", T)
    stats = done["statistics"]
    got = received(listener)
    assert set(transports(listener)) == {"SHM"}
    assert 0 < len(got) < n and got[-1] == f"hello {n - 1}"  # the newest is kept
    assert stats["delivered"] == len(got)
    # every message sent is either delivered or counted as dropped: none lost silently
    assert stats["delivered"] + stats["dropped_queue_full"] == n, stats


@pytest.mark.parametrize("hints,want", [("tcp,shm", "TCPROS"), ("dds", "DDS"), ("shm,tcp", "SHM")])
def test_transport_hints_order_shm_like_the_others(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                   hints: str, want: str) -> None:
    env = shm_env(ros_master)
    topic = f"/shm/hints_{hints.replace(',', '_')}"
    listener = spawn(mrt("listen", "--topic", topic, "--hints", hints, "--exit-after", 5, "--duration", T), env,
                     name="listener")
    listener.wait_for("ready", T)
    spawn(mrt("talk", "--topic", topic, "--count", 1000, "--rate", 50), env, name="talker")
    listener.wait_for_count("recv", 5, T)
    assert set(transports(listener)) == {want}


def test_another_unix_user_falls_back_to_dds_in_words(ros_master: harness.RosMaster, spawn: harness.Spawner,
                                                       request: pytest.FixtureRequest) -> None:
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.fail("this test runs the listener as another user: it needs root and setpriv (util-linux)")
    nobody = pwd.getpwnam("nobody")
    home = tempfile.mkdtemp(prefix="micros_rt_nobody_")  # /tmp: pytest's own directories are root's only
    os.chmod(home, 0o755)
    os.chown(home, nobody.pw_uid, nobody.pw_gid)
    request.addfinalizer(lambda: shutil.rmtree(home, ignore_errors=True))
    env = {**shm_env(ros_master), "HOME": home, "ROS_HOME": home, "ROS_LOG_DIR": home}
    topic = "/shm/two_users"
    # the clone may sit in a directory only root can enter (/root, or a home of mode 0700): the listener may read
    # and search what it needs to run (CAP_DAC_READ_SEARCH, nothing else; it writes and owns as nobody)
    listener = spawn(["setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups",
                      "--inh-caps=+dac_read_search", "--ambient-caps=+dac_read_search",
                      *mrt("listen", "--topic", topic, "--exit-after", 5, "--duration", T)], env,
                     name="other_user_listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", 1000, "--rate", 50), env, name="talker")
    listener.wait_for_count("recv", 5, T)
    assert set(transports(listener)) == {"DDS"}
    talker.wait_for(lambda e: e.get("event") == "log" and "another Unix user" in e.get("text", ""), T)


def _maps_ddsc(pid: int) -> bool:
    """Whether process ``pid`` has Cyclone DDS's library loaded (a participant, or its import)."""
    with open(f"/proc/{pid}/maps") as f:
        return "libddsc" in f.read()


def test_with_ros2_visibility_off_local_nodes_use_shm_and_load_no_dds(ros_master: harness.RosMaster,
                                                                       spawn: harness.Spawner) -> None:
    env = {**shm_env(ros_master), "MICROS_RT_ROS2": "off"}
    topic = "/shm/no_ros2"
    listener = spawn(mrt("listen", "--topic", topic, "--exit-after", 20, "--duration", T), env, name="listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", 1000, "--rate", 50, "--linger", 5), env, name="talker")
    listener.wait_for_count("recv", 20, T)
    assert set(transports(listener)) == {"SHM"}
    assert not _maps_ddsc(talker.proc.pid) and not _maps_ddsc(listener.proc.pid), \
        "a node with ROS 2 visibility off and only local peers loaded Cyclone DDS"


def test_by_default_local_nodes_use_shm_and_only_the_hosts_watcher_loads_dds(ros_master: harness.RosMaster,
                                                                             spawn: harness.Spawner) -> None:
    # the defaults (ROS 2 visibility auto): one node of the host watches the DDS domain for ROS 2 (its participant);
    # the others only look at its files. Every node used to import cyclonedds for that look (~120 ms of CPU each,
    # half of a 60-node robot's extra start-up over rospy); now only the watcher loads it
    env = shm_env(ros_master)
    topic = "/shm/one_watcher"
    listeners = [spawn(mrt("listen", "--topic", topic, "--duration", T, "--node-name", f"l{i}"), env,
                       name=f"listener_{i}") for i in range(2)]
    for listener in listeners:
        listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", 1000, "--rate", 50, "--linger", 5), env, name="talker")
    for listener in listeners:
        listener.wait_for_count("recv", 20, T)
        assert set(transports(listener)) == {"SHM"}
    nodes = [talker, *listeners]
    assert all(n.proc.poll() is None for n in nodes)  # all three running, each past several housekeeping ticks
    loaded = [n.name for n in nodes if _maps_ddsc(n.proc.pid)]
    assert len(loaded) <= 1, f"more than the host's watcher loaded Cyclone DDS: {loaded}"
    for n in nodes:
        n.stop()


def test_with_ros2_visibility_off_a_peer_on_another_host_gets_dds_on_demand(dds_domain: int,
                                                                           spawn: harness.Spawner) -> None:
    from netns import Hosts

    hosts = Hosts(2)
    hosts.up()
    try:
        envs = [{**hosts.env(i), "MICROS_RT_DISABLE_SHM": "0", "MICROS_RT_ROS2": "off"} for i in range(2)]
        topic = "/shm/other_host"
        listener = spawn(hosts.run(1, mrt("listen", "--topic", topic, "--exit-after", 20, "--duration", T)),
                         envs[1], name="listener_host1")
        listener.wait_for("ready", T)
        talker = spawn(hosts.run(0, mrt("talk", "--topic", topic, "--count", 1000, "--rate", 50, "--linger", 5)),
                       envs[0], name="talker_host0")
        got = listener.wait_for_count("recv", 20, T)
        # another network namespace is another host: shared memory is declined, DDS made on demand on both sides
        assert {e["transport"] for e in got} == {"DDS"}
        # `ip netns exec` execs the node in its own process: the pids are the nodes'
        assert _maps_ddsc(talker.proc.pid) and _maps_ddsc(listener.proc.pid)
        talker.stop()
        listener.stop()
    finally:
        hosts.down()


def test_a_local_shm_subscriber_costs_its_publisher_no_dds_writes(ros_master: harness.RosMaster,
                                                                spawn: harness.Spawner) -> None:
    """With ROS 2 visibility on, the subscriber has a DDS reader and the publisher a DDS writer, and Cyclone
    matches them; the publisher stops writing to DDS once it knows that reader is served over SHM."""
    env = shm_env(ros_master, "beside_dds")
    topic = "/shm/no_double_send"
    listener = spawn(mrt("listen", "--topic", topic, "--duration", T), env, name="listener")
    listener.wait_for("ready", T)
    talker = spawn(mrt("talk", "--topic", topic, "--count", 150, "--rate", 50, "--wait-subscribers", 1,
                       "--wait-dds-readers", 1, "--linger", 1.0), env, name="talker")
    matched = talker.wait_for("dds_matched", T)
    assert matched["n"] >= 1  # the listener's DDS reader is matched with the talker's writer
    done = talker.wait_for("done", T)
    assert done["dds_wanted"] is False, done
    listener.wait_for_count("recv", 150, T)
    assert set(transports(listener)) == {"SHM"}
