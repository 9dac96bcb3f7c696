"""Services both ways: micros_rt's advertise_service/service_client with stock rospy and real rclpy peers.

Processes (all real, see DESIGN.md): a rosmaster; tests/peers/ros1_service_peer.py as a micros_rt node
(``--impl micros_rt``, project venv) and as a stock rospy node (/usr/bin/python3, no micros_rt);
tests/peers/ros2_service_peer.py with rclpy and Fast DDS (.venv-ros2). Types: std_srvs SetBool and Trigger
(Trigger's request is empty: ROS 2's one-byte placeholder) and test_msgs/BasicTypes, a user's srv that no ROS 1
package has (built at run time on the ROS 1 side, every primitive type). The servers share a prefix per run.
"""

from __future__ import annotations

import json
import os
import signal
from typing import Any, Dict, Iterator, List, Set

import pytest

import harness

pytestmark = pytest.mark.integration

P = f"/svc{os.getpid()}"
PEER1 = str(harness.PEERS_DIR / "ros1_service_peer.py")
PEER2 = str(harness.PEERS_DIR / "ros2_service_peer.py")
T = 30.0  # bound on a peer's whole plan

BASIC: Dict[str, Any] = {
    "bool_value": True, "byte_value": 5, "char_value": 65, "float32_value": 1.5, "float64_value": 2.25,
    "int8_value": -8, "uint8_value": 200, "int16_value": -1600, "uint16_value": 60000, "int32_value": -320000,
    "uint32_value": 4000000000, "int64_value": -2 ** 40, "uint64_value": 2 ** 63, "string_value": "héllo wörld",
}


def ros1_peer(impl: str, mode: str, spec: List[Dict[str, Any]]) -> List[str]:
    python = harness.MICROS_RT_PYTHON if impl == "micros_rt" else harness.STOCK_PYTHON
    key = "--services" if mode == "serve" else "--plan"
    return [python, PEER1, "--impl", impl, mode, key, json.dumps(spec)]


def ros2_peer(mode: str, spec: List[Dict[str, Any]]) -> List[str]:
    return [harness.ROS2_PYTHON, PEER2, mode, "--services" if mode == "serve" else "--plan", json.dumps(spec)]


def by_label(peer: harness.Peer, label: str, kind: str) -> Dict[str, Any]:
    found = [e for e in peer.events(kind) if e.get("label") == label]
    assert found, f"no {kind} event for {label}: {peer.events()[-8:]}\n{peer.stderr_tail()}"
    return found[0]


@pytest.fixture(scope="module")
def servers(ros_master: harness.RosMaster) -> Iterator[Dict[str, harness.Peer]]:
    """A micros_rt, a stock rospy and an rclpy server, started together (startup dominates this file's time)."""
    env = dict(ros_master.env)
    peers = {
        "micros_rt": harness.Peer(ros1_peer("micros_rt", "serve", [
            {"name": f"{P}/mrt/set_bool", "type": "std_srvs/SetBool", "mode": "fail"},
            {"name": f"{P}/mrt/trigger", "type": "std_srvs/Trigger"},
            {"name": f"{P}/mrt/basic", "type": "test_msgs/BasicTypes"}]), env, name="mrt_server"),
        "rospy": harness.Peer(ros1_peer("rospy", "serve", [
            {"name": f"{P}/r1/set_bool", "type": "std_srvs/SetBool", "mode": "fail"}]), env, name="stock_server"),
        "rclpy": harness.Peer(ros2_peer("serve", [
            {"name": f"{P}/r2/set_bool", "type": "std_srvs/srv/SetBool"},
            {"name": f"{P}/r2/trigger", "type": "std_srvs/srv/Trigger"},
            {"name": f"{P}/r2/basic", "type": "test_msgs/srv/BasicTypes"},
            {"name": f"{P}/r2/silent", "type": "std_srvs/srv/SetBool", "mode": "silent"}]), env, name="ros2_server"),
    }
    try:
        ready = peers["micros_rt"].wait_for("ready", T)
        assert ready["ros2"] == [f"{P}/mrt/set_bool", f"{P}/mrt/trigger", f"{P}/mrt/basic"], ready
        peers["rospy"].wait_for("ready", T)
        peers["rclpy"].wait_for("ready", T)
        yield peers
    finally:
        for peer in peers.values():
            peer.stop()
        remove_orphaned_shm(KILLED_SHM)


def test_stock_rospy_client_calls_micros_rt_server(servers: Dict[str, harness.Peer], spawn: Any) -> None:
    client = spawn(ros1_peer("rospy", "call", [
        {"label": "true", "name": f"{P}/mrt/set_bool", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 10},
        {"label": "raises", "name": f"{P}/mrt/set_bool", "type": "std_srvs/SetBool", "args": {"data": False}},
        {"label": "wrong type", "name": f"{P}/mrt/set_bool", "type": "std_srvs/Trigger"},
        {"label": "trigger", "name": f"{P}/mrt/trigger", "type": "std_srvs/Trigger"},
        {"label": "user srv", "name": f"{P}/mrt/basic", "type": "test_msgs/BasicTypes", "args": BASIC},
        {"label": "still serving", "name": f"{P}/mrt/set_bool", "type": "std_srvs/SetBool", "args": {"data": True},
         "count": 50}]))
    client.wait_for("done", T)
    assert by_label(client, "true", "response")["fields"] == {"success": True,
                                                              "message": f"micros_rt {P}/mrt/set_bool got True"}
    # the handler's exception reaches the stock caller in words (rospy's own service semantics)
    assert "refuses False" in by_label(client, "raises", "error")["message"]
    # a request of another type (md5sum) is refused in words at the connection; the server keeps serving
    assert "md5" in by_label(client, "wrong type", "error")["message"].lower()
    assert by_label(client, "trigger", "response")["fields"]["message"] == f"micros_rt {P}/mrt/trigger triggered"
    assert by_label(client, "user srv", "response")["fields"] == BASIC
    summary = by_label(client, "still serving", "summary")
    assert (summary["ok"], summary["n_errors"]) == (50, 0), summary


def test_rclpy_client_calls_micros_rt_server(servers: Dict[str, harness.Peer], spawn: Any) -> None:
    # a client the server can never answer (its response reader is transient-local; the helper's writer volatile):
    # rclpy 7 only warns when the RMW gives up on a response, so the helper must see that itself, send it again
    # (a client's reader discovered late, as under load) and at last count it lost and say so. The client calls for
    # 20 s, well beyond the 10 s the helper tries (its first calls may go before its writer matched the server):
    # a client gone is no loss (Fast DDS then sends to nobody and does not warn)
    deaf = spawn(ros2_peer("call", [
        {"label": "deaf", "name": f"{P}/mrt/set_bool", "type": "std_srvs/srv/SetBool", "args": {"data": True},
         "response_durability": "transient_local", "count": 10, "timeout": 2, "wait": 15}]), name="ros2_deaf_client")
    client = spawn(ros2_peer("call", [
        {"label": "true", "name": f"{P}/mrt/set_bool", "type": "std_srvs/srv/SetBool", "args": {"data": True},
         "wait": 15},
        {"label": "many", "name": f"{P}/mrt/set_bool", "type": "std_srvs/srv/SetBool", "args": {"data": True},
         "count": 200},
        {"label": "raises", "name": f"{P}/mrt/set_bool", "type": "std_srvs/srv/SetBool", "args": {"data": False},
         "timeout": 1.0},
        {"label": "trigger", "name": f"{P}/mrt/trigger", "type": "std_srvs/srv/Trigger"},
        {"label": "user srv", "name": f"{P}/mrt/basic", "type": "test_msgs/srv/BasicTypes", "args": BASIC},
        {"label": "still serving", "name": f"{P}/mrt/set_bool", "type": "std_srvs/srv/SetBool",
         "args": {"data": True}}]))
    # two more rclpy clients at once, each with its own request: each gets its own answers (request identity)
    echo = {"name": f"{P}/mrt/basic", "type": "test_msgs/srv/BasicTypes", "count": 100, "echo_check": True,
            "wait": 15}
    concurrent = [spawn(ros2_peer("call", [{**echo, "label": "echo", "args": {**BASIC, "string_value": who}}]),
                        name=f"ros2_echo_{who}") for who in ("a", "b")]
    client.wait_for("done", T)
    for peer in concurrent:
        peer.wait_for("done", T)
        summary = by_label(peer, "echo", "summary")
        # never an answer to the other client's request; a call left unanswered now and then with two rclpy
        # clients at once is ROS 2's own (rclpy to rclpy here: ~1 call in 1,200-2,400), so one is tolerated
        assert summary["mismatches"] == 0 and summary["ok"] >= 99, summary
    assert by_label(client, "true", "response")["fields"] == {"success": True,
                                                              "message": f"micros_rt {P}/mrt/set_bool got True"}
    many = by_label(client, "many", "summary")
    # as for the echo clients above: three rclpy clients call at once here, one call left unanswered is ROS 2's
    assert many["ok"] >= 199 and many["n_errors"] <= 1 and many["ok"] + many["n_errors"] == 200, many
    # ROS 2 services carry no error: the rclpy caller's own timeout tells it; the server says why in its log
    assert by_label(client, "raises", "error")["kind"] == "Timeout"
    harness.wait_until(lambda: "ROS 2 services carry no error" in servers["micros_rt"].stderr_tail(200), 5.0,
                       message="the server's warning about the failed ROS 2 request")
    assert by_label(client, "trigger", "response")["fields"] == {"success": True,
                                                                 "message": f"micros_rt {P}/mrt/trigger triggered"}
    assert by_label(client, "user srv", "response")["fields"] == BASIC
    assert by_label(client, "still serving", "response")["fields"]["success"] is True
    deaf.wait_for("done", T)
    assert by_label(deaf, "deaf", "summary")["ok"] == 0
    harness.wait_until(lambda: f"a response of {P}/mrt/set_bool is lost" in servers["micros_rt"].stderr_tail(200),
                       T, message="the helper's word on the response its client could never take:\n"
                       + servers["micros_rt"].stderr_tail(60) + "\n" + str(deaf.events()[-4:]))


def test_micros_rt_client_calls_rospy_and_rclpy_servers(servers: Dict[str, harness.Peer], spawn: Any) -> None:
    client = spawn(ros1_peer("micros_rt", "call", [
        {"label": "ros1", "name": f"{P}/r1/set_bool", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 10, "timeout": 5},
        {"label": "ros1 raises", "name": f"{P}/r1/set_bool", "type": "std_srvs/SetBool", "args": {"data": False},
         "timeout": 5},
        {"label": "ros2", "name": f"{P}/r2/set_bool", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 15, "timeout": 5},
        {"label": "ros2 many", "name": f"{P}/r2/set_bool", "type": "std_srvs/SetBool", "args": {"data": False},
         "count": 200, "timeout": 5},
        {"label": "ros2 trigger", "name": f"{P}/r2/trigger", "type": "std_srvs/Trigger", "wait": 10, "timeout": 5},
        {"label": "ros2 user srv", "name": f"{P}/r2/basic", "type": "test_msgs/BasicTypes", "args": BASIC,
         "wait": 10, "timeout": 5},
        {"label": "micros_rt", "name": f"{P}/mrt/trigger", "type": "std_srvs/Trigger", "wait": 10, "timeout": 5},
        {"label": "ros2 concurrent", "name": f"{P}/r2/basic", "type": "test_msgs/BasicTypes", "args": BASIC,
         "timeout": 5, "count": 200, "threads": 4, "echo_check": True}]))
    client.wait_for("done", T)
    ros1 = by_label(client, "ros1", "response")
    assert (ros1["side"], ros1["fields"]) == ("ROS 1", {"success": True, "message": f"rospy {P}/r1/set_bool got True"})
    message = by_label(client, "ros1 raises", "error")["message"]
    assert "refuses False" in message and "b'" not in message, message
    ros2 = by_label(client, "ros2", "response")
    assert (ros2["side"], ros2["fields"]) == ("ROS 2", {"success": True, "message": f"rclpy {P}/r2/set_bool got True"})
    many = by_label(client, "ros2 many", "summary")
    assert (many["ok"], many["n_errors"], many["last"]["success"]) == (200, 0, False), many
    assert by_label(client, "ros2 trigger", "response")["fields"]["message"] == f"rclpy {P}/r2/trigger triggered"
    assert by_label(client, "ros2 user srv", "response")["fields"] == BASIC
    # a micros_rt server is in the master too: two micros_rt nodes talk TCPROS
    mrt = by_label(client, "micros_rt", "response")
    assert (mrt["side"], mrt["fields"]["message"]) == ("ROS 1", f"micros_rt {P}/mrt/trigger triggered"), mrt
    # four threads calling through one client at once: each call gets the answer to its own request
    concurrent = by_label(client, "ros2 concurrent", "summary")
    assert concurrent["mismatches"] == 0 and concurrent["ok"] >= 199, concurrent  # (as above)


def shm_files(pid: int) -> Set[str]:
    """The /dev/shm files process ``pid`` maps or holds open (Fast DDS's segments and port files, with the lock
    file ``<name>_el`` and the semaphore ``sem.<name>_mutex`` that go with each)."""
    names: Set[str] = set()
    try:
        with open(f"/proc/{pid}/maps") as f:
            names |= {line.split("/dev/shm/", 1)[1].split(" (deleted)")[0].strip() for line in f if "/dev/shm/" in line}
        for fd in os.listdir(f"/proc/{pid}/fd"):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("/dev/shm/"):
                names.add(target[len("/dev/shm/"):])
    except OSError:
        pass
    return names


def remove_orphaned_shm(names: Set[str]) -> None:
    """Remove those of ``names`` (and their companions) no live process uses: what a SIGKILLed Fast DDS process
    left in /dev/shm."""
    names = names | {f"{n}_el" for n in names} | {f"sem.{n}_mutex" for n in names}
    live: Set[str] = set()
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            live |= shm_files(int(entry))
    for name in names - live:
        try:
            os.unlink(f"/dev/shm/{name}")
        except OSError:
            pass


#: /dev/shm files of the ROS 2 peer this module kills, removed at the end when no one maps them any more
KILLED_SHM: Set[str] = set()


def test_bad_input_reaches_the_caller_in_words(servers: Dict[str, harness.Peer], spawn: Any) -> None:
    dying1 = spawn(ros1_peer("rospy", "serve", [{"name": f"{P}/r1/dying", "type": "std_srvs/SetBool",
                                                  "mode": "slow"}]), name="dying_ros1")
    dying2 = spawn(ros2_peer("serve", [{"name": f"{P}/r2/dying", "type": "std_srvs/srv/SetBool",
                                        "mode": "silent"}]), name="dying_ros2")
    dying1.wait_for("ready", T)
    dying2.wait_for("ready", T)
    client = spawn(ros1_peer("micros_rt", "call", [
        {"label": "wrong type", "name": f"{P}/r2/set_bool", "type": "std_srvs/SetBool",
         "request_type": "std_msgs/String", "args": {"data": "not a SetBool"}, "wait": 15, "timeout": 2},
        {"label": "bad value", "name": f"{P}/r2/set_bool", "type": "std_srvs/SetBool", "args": {"data": "yes"},
         "timeout": 2},
        {"label": "never answers", "name": f"{P}/r2/silent", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 10, "timeout": 1.0},
        {"label": "ros1 dies", "name": f"{P}/r1/dying", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 10, "timeout": 8},
        {"label": "ros2 dies", "name": f"{P}/r2/dying", "type": "std_srvs/SetBool", "args": {"data": True},
         "wait": 10, "timeout": 2},
        {"label": "nobody", "name": f"{P}/nobody", "type": "std_srvs/SetBool", "args": {"data": True},
         "timeout": 1},
        {"label": "wait nobody", "name": f"{P}/nobody", "type": "std_srvs/SetBool", "wait": 0.5},
        {"label": "still works", "name": f"{P}/r2/set_bool", "type": "std_srvs/SetBool", "args": {"data": True},
         "timeout": 2}]))
    # kill each slow server once it holds the call
    dying1.wait_for("served", T)
    dying1.proc.send_signal(signal.SIGKILL)
    dying2.wait_for("served", T)
    KILLED_SHM.update(shm_files(dying2.pid))
    dying2.proc.send_signal(signal.SIGKILL)
    client.wait_for("done", T)

    wrong = by_label(client, "wrong type", "error")
    assert wrong["kind"] == "TypeError" and "takes a std_srvs/SetBoolRequest, got a std_msgs/String" in wrong["message"]
    bad = by_label(client, "bad value", "error")
    assert bad["kind"] == "TypeError" and "data" in bad["message"], bad
    silent = by_label(client, "never answers", "error")
    assert silent["kind"] == "ServiceTimeoutError" and "did not answer within 1 s" in silent["message"]
    assert 0.9 < silent["elapsed"] < 3.0, silent  # the 1 s timeout, and room for a loaded machine; not a hang
    died1 = by_label(client, "ros1 dies", "error")
    assert died1["kind"] == "ServiceError" and died1["elapsed"] < 8.0, died1
    died2 = by_label(client, "ros2 dies", "error")
    assert died2["kind"] in ("ServiceError", "ServiceTimeoutError") and died2["elapsed"] < 4.0, died2
    nobody = by_label(client, "nobody", "error")
    assert nobody["kind"] == "ServiceUnavailableError" and "no ROS 1 server" in nobody["message"], nobody
    waited = by_label(client, "wait nobody", "unavailable")
    assert waited["kind"] == "ServiceTimeoutError" and waited["elapsed"] < 3.0, waited
    assert by_label(client, "still works", "response")["fields"]["success"] is True
    # the servers of the module kept serving through all this
    assert servers["micros_rt"].alive() and servers["rclpy"].alive() and servers["rospy"].alive()
