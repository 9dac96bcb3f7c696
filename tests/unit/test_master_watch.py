"""micros_rt.transports.tcpros.patches.MasterWatch against a stand-in master in a subprocess (an XML-RPC server answering
getPid, as rosmaster does): the watch holds one idle connection, notices the process's end through it, and
re-registers when a master answers again with another pid. No rospy node."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from typing import Iterator, List, Tuple

import pytest

from micros_rt.transports.tcpros import patches as rospy_compat

SERVER = """
import sys, threading
from xmlrpc.server import SimpleXMLRPCServer
from socketserver import ThreadingMixIn
class Server(ThreadingMixIn, SimpleXMLRPCServer):
    daemon_threads = True
    allow_reuse_address = True
server = Server(("127.0.0.1", int(sys.argv[1])), logRequests=False)
calls = []
def getPid(caller_id):
    calls.append(caller_id)
    print("getPid", flush=True)
    return [1, "", int(sys.argv[2])]
server.register_function(getPid)
print("ready", flush=True)
server.serve_forever()
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(port: int, pid: int) -> "subprocess.Popen[str]":
    proc = subprocess.Popen([sys.executable, "-c", SERVER, str(port), str(pid)], stdout=subprocess.PIPE, text=True)
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
