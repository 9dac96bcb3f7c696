"""micros_rt.transports.tcpros.patches.MasterWatch against a stand-in master in a subprocess (an XML-RPC server answering
getPid, as rosmaster does): the watch holds one idle connection, notices the process's end through it, and
re-registers when a master answers again with another pid. No rospy node."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from typing import Any, Iterator, List, Tuple

import pytest
import rospy.core

from micros_rt.transports.tcpros import patches as rospy_compat

SERVER = """
import os, sys, threading, time
from xmlrpc.server import SimpleXMLRPCServer
from socketserver import ThreadingMixIn
class Server(ThreadingMixIn, SimpleXMLRPCServer):
    daemon_threads = True
    allow_reuse_address = True
server = Server(("127.0.0.1", int(sys.argv[1])), logRequests=False)
calls = []
SLOW = sys.argv[3] if len(sys.argv) > 3 else ""   # while this file exists, getPid takes 3 s (a busy master)
KNOWN = sys.argv[4] if len(sys.argv) > 4 else ""  # the one node URI lookupNode knows
def getPid(caller_id):
    calls.append(caller_id)
    print("getPid", flush=True)
    if SLOW and os.path.exists(SLOW):
        time.sleep(3)
    return [1, "", int(sys.argv[2])]
def lookupNode(caller_id, node):
    print("lookupNode", flush=True)
    return [1, "node", KNOWN] if KNOWN else [-1, "unknown node [%s]" % node, ""]
server.register_function(getPid)
server.register_function(lookupNode)
print("ready", flush=True)
server.serve_forever()
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(port: int, pid: int, *extra: str) -> "subprocess.Popen[str]":
    proc = subprocess.Popen([sys.executable, "-c", SERVER, str(port), str(pid), *extra], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


def established(port: int) -> int:
    """Established TCP connections to ``port`` on loopback, from the kernel."""
    out = subprocess.run(["ss", "-tnH", "state", "established", f"( dport = :{port} )"], capture_output=True,
                         text=True, timeout=10).stdout
    return len(out.splitlines())


@pytest.fixture
def reregistered(monkeypatch: pytest.MonkeyPatch) -> Iterator[List[int]]:
    calls: List[int] = []

    def reregister_all() -> Tuple[int, int, int]:
        calls.append(1)
        return 0, 0, 0

    monkeypatch.setattr(rospy_compat, "reregister_all", reregister_all)
    monkeypatch.setattr(rospy_compat, "caller_id", lambda: "/watch_test")
    yield calls


def test_the_watch_holds_one_idle_connection_and_asks_the_pid_only_when_it_connects(reregistered: List[int]) -> None:
    port = free_port()
    master = start(port, 100)
    watch = rospy_compat.MasterWatch(f"http://127.0.0.1:{port}/", period=0.0)
    try:
        for _ in range(20):
            watch.check()
        assert established(port) == 1       # one connection, kept: no connect per check
        master.kill()                        # the process ends: the kernel closes the connection
        master.wait(10)
        deadline = time.monotonic() + 10
        while watch._down_since is None and time.monotonic() < deadline:
            watch.check()
            time.sleep(0.01)
        assert watch._down_since is not None and reregistered == []
        master = start(port, 200)            # a new master on the same port: another pid
        deadline = time.monotonic() + 10
        while not reregistered and time.monotonic() < deadline:
            watch.check()
            time.sleep(0.01)
        assert reregistered == [1] and watch._down_since is None and watch._pid == 200
        for _ in range(20):
            watch.check()
        assert reregistered == [1] and established(port) == 1
    finally:
        watch.close()
        master.kill()
        master.wait(10)
    assert master.stdout is not None
    assert master.stdout.read().count("getPid") == 1  # the second master was asked once, when the watch connected


@pytest.mark.parametrize("knows", [True, False], ids=["master_knows_the_node", "master_forgot_the_node"])
def test_a_master_too_busy_to_answer_then_back_is_re_registered_with_only_if_it_lost_the_node(
        reregistered: List[int], monkeypatch: pytest.MonkeyPatch, tmp_path: Any, knows: bool) -> None:
    """60 nodes starting at once kept rosmaster from answering getPid within 2 s; each node's watch then took
    the master for gone and, once it answered, re-registered every topic, adding to the load that slowed it.
    The same master (it still has this node at this node's URI) is not re-registered with; one that lost the node
    (restarted in a container with the same pid) is."""
    me = "http://127.0.0.1:1/"
    monkeypatch.setattr(rospy.core, "get_node_uri", lambda: me)
    port = free_port()
    slow = tmp_path / "slow"
    slow.touch()
    master = start(port, 100, str(slow), me if knows else "")
    watch = rospy_compat.MasterWatch(f"http://127.0.0.1:{port}/", period=0.0)
    try:
        watch.check()                        # connected, but getPid took longer than the watch waits
        assert watch._down_since is not None and reregistered == []
        slow.unlink()
        deadline = time.monotonic() + 20
        while watch._down_since is not None and time.monotonic() < deadline:
            watch.check()
            time.sleep(0.05)
        assert watch._down_since is None and watch._pid == 100
        assert reregistered == ([] if knows else [1])
    finally:
        watch.close()
        master.kill()
        master.wait(10)
    assert master.stdout is not None
    assert "lookupNode" in master.stdout.read()  # asked, not assumed
