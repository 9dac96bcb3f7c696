"""Stock roscpp nodes in services across ROS 1 and ROS 2 (issue 35): a roscpp std_srvs/SetBool client and server
with micros_rt's ``advertise_service``/``service_client`` (ROS 1, TCPROS through the master) and with rclpy
through ``micros-rt relay``'s ``ros2:`` section.

Processes (all real): tests/peers/roscpp_setbool.cpp, built here once per session with g++ against Debian's
libroscpp-dev and libstd-srvs-dev (a failed build fails the tests with the compiler's message); tests/peers/
ros1_service_peer.py as a micros_rt node (project venv); tests/peers/ros2_service_peer.py with rclpy and Fast DDS
(.venv-ros2, loopback only); ``micros-rt relay``; a rosmaster (the session's for the ROS 1 tests, one of its own
for the relay's). Names carry this run's pid.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Iterator, List

import pytest

import harness
from helpers import CxxPeerBuild, relay_argv, ros1_service_peer, ros2_service_peer

pytestmark = pytest.mark.integration

P = f"/roscpp{os.getpid()}"
T = 30.0  # generous bound on any one wait (a 2-core machine, perhaps busy)
TRUE = {"success": True, "message": "roscpp got true"}
FALSE = {"success": False, "message": "roscpp got false"}


@pytest.fixture(scope="session")
def roscpp_setbool(tmp_path_factory: pytest.TempPathFactory) -> Iterator[CxxPeerBuild]:
    """The roscpp peer's build, started once per session; ``.binary()`` waits for it (and fails in words)."""
    # std_srvs is headers only (libstd-srvs-dev has no .pc file)
    build = CxxPeerBuild(harness.PEERS_DIR / "roscpp_setbool.cpp", tmp_path_factory.mktemp("roscpp"), ("roscpp",))
    try:
        yield build
    finally:
        build.close()


def by_label(peer: harness.Peer, label: str, kind: str) -> Dict[str, Any]:
    found = [e for e in peer.events(kind) if e.get("label") == label]
    assert found, f"no {kind} event for {label}: {peer.events()[-8:]}\n{peer.stderr_tail()}"
    return found[0]


def roscpp_calls(client: harness.Peer, n: int) -> List[Dict[str, Any]]:
    """The roscpp client's ``n`` answers, once it is done; its summary must count no failure."""
    client.wait_for("done", 2 * T)  # its wait for the service (up to T) and its calls
    summary = client.events("summary")[0]
    assert (summary["calls"], summary["ok"], summary["failures"], summary["wrong"]) == (n, n, 0, 0), \
        (summary, client.events("error")[:3], client.stderr_tail())
    responses = client.events("response")
    slowest = max(responses, key=lambda r: float(r["us"]))
    print(f"{client.name}: {n} calls, p50 {summary['p50_us']:.0f} us, p99 {summary['p99_us']:.0f} us, slowest: "
          f"call {slowest['i']}, {slowest['us']:.0f} us")
    assert [r["i"] for r in responses] == list(range(n)), responses[:5]
    return responses


def test_roscpp_client_calls_micros_rt_server(roscpp_setbool: CxxPeerBuild, spawn: Any) -> None:
    name = f"{P}/mrt/set_bool"
    # the server's start-up (micros_rt and its ROS 2 helper) overlaps the build
    server = spawn(ros1_service_peer("micros_rt", "serve", [{"name": name, "type": "std_srvs/SetBool"}],
                                     "--quiet"), name="mrt_server")
    client = spawn([roscpp_setbool.binary(), "client", name, "200", str(T)], name="roscpp_client")
    server.wait_for("ready", T)
    for r in roscpp_calls(client, 200):
        assert (r["data"], r["success"], r["message"]) == (
            r["i"] % 2 == 0, r["data"], f"micros_rt {name} got {'True' if r['data'] else 'False'}"), r


def test_micros_rt_client_calls_roscpp_server(roscpp_setbool: CxxPeerBuild, spawn: Any) -> None:
    name = f"{P}/cpp/set_bool"
    client = spawn(ros1_service_peer("micros_rt", "call", [
        {"label": "true", "name": name, "type": "std_srvs/SetBool", "args": {"data": True}, "wait": T, "timeout": 5},
        {"label": "false", "name": name, "type": "std_srvs/SetBool", "args": {"data": False}, "timeout": 5},
        {"label": "many", "name": name, "type": "std_srvs/SetBool", "args": {"data": True}, "count": 100,
         "timeout": 5}]), name="mrt_client")
    server = spawn([roscpp_setbool.binary(), "server", name], name="roscpp_server")
    assert server.wait_for("ready", T)["name"] == name
    client.wait_for("done", 2 * T)  # its wait for the service (up to T) and its calls
    true = by_label(client, "true", "response")
    assert (true["side"], true["fields"]) == ("ROS 1", TRUE), true
    false = by_label(client, "false", "response")
    assert (false["side"], false["fields"]) == ("ROS 1", FALSE), false
    many = by_label(client, "many", "summary")
    assert (many["ok"], many["n_errors"], many["last"]) == (100, 0, TRUE), many
    print(f"micros_rt client -> roscpp server: 100 calls, p50 {many['p50_us']:.0f} us, p99 {many['p99_us']:.0f} us")
    served = server.wait_for_count("served", 102, T)
    assert [e["data"] for e in served[:2]] == [True, False], served[:2]


def test_relay_carries_roscpp_services_to_and_from_ros2(fresh_master: harness.RosMaster,
                                                        roscpp_setbool: CxxPeerBuild, spawn: Any,
                                                        tmp_path: Path) -> None:
    exported, imported = f"{P}/relayed_cpp/set_bool", f"{P}/r2/set_bool"
    config = tmp_path / "relay.yaml"
    config.write_text(f"graph: roscpp\nros2:\n  export: {{{exported}: {{}}}}   # the roscpp server, to ROS 2\n"
                      f"  import: {{{imported}: {{}}}}   # the rclpy server, to ROS 1\n")
    env = fresh_master.env
    # everyone starts at once (start-up and discovery overlap); each client waits for its service
    relay = spawn(relay_argv(config), env=env, name="relay")
    ros2_server = spawn(ros2_service_peer("serve", [{"name": imported, "type": "std_srvs/srv/SetBool"}]), env=env,
                        name="rclpy_server")
    ros2_client = spawn(ros2_service_peer("call", [
        {"label": "true", "name": exported, "type": "std_srvs/srv/SetBool", "args": {"data": True}, "wait": T,
         "timeout": 5},
        {"label": "false", "name": exported, "type": "std_srvs/srv/SetBool", "args": {"data": False}, "timeout": 5},
        {"label": "many", "name": exported, "type": "std_srvs/srv/SetBool", "args": {"data": False}, "count": 50,
         "timeout": 5}]), env=env, name="rclpy_client")
    binary = roscpp_setbool.binary()
    server = spawn([binary, "server", exported], env=env, name="roscpp_server")
    client = spawn([binary, "client", imported, "50", str(T)], env=env, name="roscpp_client")
    try:
        ros2_client.wait_for("done", 2 * T)  # the wait for the service (up to T) and the calls
        client.wait_for("done", 2 * T)
    except AssertionError as exc:
        raise AssertionError(f"{exc}\nrelay's last events: {relay.events()[-3:]}\nrelay's stderr:\n"
                             f"{relay.stderr_tail()}") from None
    # ROS 2 -> relay -> roscpp: the roscpp server's answers reach the rclpy client as it gave them
    assert by_label(ros2_client, "true", "response")["fields"] == TRUE
    assert by_label(ros2_client, "false", "response")["fields"] == FALSE
    many = by_label(ros2_client, "many", "summary")
    assert (many["ok"], many["n_errors"], many["last"]) == (50, 0, FALSE), many
    print(f"rclpy client -> relay -> roscpp server: 50 calls, p50 {many['p50_us']:.0f} us, "
          f"p99 {many['p99_us']:.0f} us")
    assert [e["data"] for e in server.wait_for_count("served", 52, T)[:2]] == [True, False]
    # roscpp -> relay -> ROS 2: the rclpy server's answers reach the roscpp client as it gave them
    for r in roscpp_calls(client, 50):
        assert (r["data"], r["success"], r["message"]) == (
            r["i"] % 2 == 0, r["data"], f"rclpy {imported} got {'True' if r['data'] else 'False'}"), r
    assert ros2_server.wait_for_count("served", 50, T)
