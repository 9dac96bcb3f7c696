"""What adding a negotiated transport takes, measured: the toy of :mod:`contract.toy_negotiated` (its module, and
one call to register it; no file of micros_rt touched), run end to end through the public API in real
processes with a real rosmaster.

One process advertises a topic and subscribes to it with ``TransportHints.from_names(["TOY", "TCPROS"])``: the
toy is negotiated, and the subscription's time filter, enforced by the core, applies to its messages. A second
process subscribes with the same hints: the publisher declines TOY in words (another process) and serves it over
TCPROS beside the toy, as a publisher on another host declines shared memory.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any, Dict

import harness

TESTS = Path(__file__).resolve().parents[1]

_COMMON = """
import dataclasses, json, sys, time
sys.path.insert(0, %r)
import micros_rt
from micros_rt.extend import register_negotiated_transport
from micros_rt.negotiation import TransportHints
from micros_rt.qos import SubscribeQoSOptions
from std_msgs.msg import String
from contract.toy_negotiated import TOY, TOY_TRANSPORT

register_negotiated_transport(TOY_TRANSPORT)
hints = TransportHints.from_names([TOY, "TCPROS"])

def wait(pred, what, timeout=60.0):
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise SystemExit("timed out waiting for " + what)
        time.sleep(0.02)
""" % str(TESTS)

_PUBLISHER = _COMMON + """
micros_rt.init_node("toy_pub")
nh = micros_rt.NodeHandle()
pub = nh.advertise("/toy_chatter", String, 10)
toy_got = []
toy = nh.subscribe_with_qos("/toy_chatter", String, toy_got.append, 10,
                            SubscribeQoSOptions(time_filter_duration=1.0, ordered_by_sending_timestamp=False),
                            transport_hints=hints)
print(json.dumps({"event": "ready"}) + "\\n", end="", flush=True)
# this process's subscriber and the other process's: two links, one of them TOY
wait(lambda: pub.get_num_connections() >= 2, "two subscribers")
wait(lambda: toy.connection_transports(), "the subscription connected")
for i in range(5):
    pub.publish(String(data="m%d" % i))   # one burst: the time filter lets the first through
time.sleep(1.2)                           # past the 1 s filter period (the duration under test)
pub.publish(String(data="after"))
wait(lambda: len(toy_got) >= 2, "the toy's two")
print(json.dumps({"event": "done", "toy": [m.data for m in toy_got],
                  "toy_transport": [m._connection_header["transport"] for m in toy_got],
                  "toy_links": toy.connection_transports(), "toy_stats": dataclasses.asdict(toy.statistics())}) + "\\n", end="",
      flush=True)
sys.stdin.readline()                      # until the other process has its messages
micros_rt.shutdown()
"""

_OTHER = _COMMON + """
micros_rt.init_node("toy_other")
nh = micros_rt.NodeHandle()
got = []
sub = nh.subscribe("/toy_chatter", String, got.append, 10, hints)
wait(lambda: len(got) >= 6, "six messages")
print(json.dumps({"event": "done", "got": [m.data for m in got], "links": sub.connection_transports()}) + "\\n", end="",
      flush=True)
micros_rt.shutdown()
"""


def _lines(proc: "subprocess.Popen[str]") -> Dict[str, Any]:
    assert proc.stdout is not None
    while True:
        line = proc.stdout.readline()
        assert line, (proc.stderr.read() if proc.stderr else "")[-3000:]
        if line.startswith("{"):   # rospy prints the node's INFO log lines on stdout too
            break
    event: Dict[str, Any] = json.loads(line)
    return event


def test_a_toy_negotiated_transport_runs_end_to_end_through_the_public_api(ros_master: harness.RosMaster) -> None:
    publisher = subprocess.Popen([harness.MICROS_RT_PYTHON, "-c", _PUBLISHER], env=ros_master.env, text=True,
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    other = None
    try:
        assert _lines(publisher)["event"] == "ready"
        other = subprocess.Popen([harness.MICROS_RT_PYTHON, "-c", _OTHER], env=ros_master.env, text=True,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        done = _lines(publisher)
        assert done["event"] == "done", done
        # negotiated as TOY in the publisher's process, its messages through the core's admission
        assert list(done["toy_links"].values()) == ["TOY"], done
        assert done["toy"] == ["m0", "after"] and set(done["toy_transport"]) == {"TOY"}, done
        assert done["toy_stats"]["dropped_filtered"] == 4, done
        # another process: TOY declined, the next protocol taken; the same publication serves both
        theirs = _lines(other)
        assert list(theirs["links"].values()) == ["TCPROS"], theirs
        assert theirs["got"] == ["m0", "m1", "m2", "m3", "m4", "after"], theirs
    finally:
        for proc in (publisher, other):
            if proc is None:
                continue
            if proc.stdin is not None:
                try:
                    proc.stdin.close()
                except OSError:
                    pass
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    log = publisher.stderr.read() if publisher.stderr else ""
    assert publisher.returncode == 0, log[-3000:]
    assert "/toy_other is process" in log and "the toy bus reaches only process" in log, log[-3000:]  # in words
