"""The relay carries a type whose message package its hosts do not have (issue 21: "learns message types at run
time, no rebuild and no message package needed on the relay's host for types it only carries").

``mrt_runtime/Reading`` exists nowhere as a package: the stock rospy talker in robot A and the stock listener in
robot B build it from its definition with genpy (``--definition``), as a node of a package the relays' hosts lack
would have it compiled. Robot A's relay learns it from the talker's connection header, robot B's from the
definition in A's DDS writer tag; both use the classes genpy builds, nested custom type included.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Tuple

import harness
from helpers import stock_listener, stock_talker
from test_relay import _stats_with, relay, robots  # noqa: F401  (robots: the two-master fixture)

TYPE = "mrt_runtime/Reading"
DEFINITION = """\
std_msgs/Header header
string data
mrt_runtime/Sample sample
================================================================================
MSG: std_msgs/Header
uint32 seq
time stamp
string frame_id
================================================================================
MSG: mrt_runtime/Sample
float64 value
uint8[] raw
"""


def test_a_type_without_its_package_crosses_between_graphs(
        robots: Tuple[harness.RosMaster, harness.RosMaster], spawn: harness.Spawner, tmp_path: Path) -> None:
    a, b = robots
    absent = subprocess.run([str(harness.REPO_ROOT / ".venv" / "bin" / "python"), "-c",
                             f"import roslib.message; print(roslib.message.get_message_class('{TYPE}'))"],
                            capture_output=True, text=True, timeout=60)
    assert absent.stdout.strip() == "None", absent  # the relays' Python really has no such package

    definition = tmp_path / "Reading.msg"
    definition.write_text(DEFINITION)
    (tmp_path / "a.yaml").write_text("graph: robot_a\nexport:\n  /reading: {}\n")
    (tmp_path / "b.yaml").write_text("graph: robot_b\nimport:\n  /robot_a/reading: {}\n")
    spawn(stock_talker("--topic", "/reading", "--type", TYPE, "--definition", definition, "--rate", 20,
                       "--count", 0, "--duration", 120), env=a.env)
    relay_a = spawn(relay(tmp_path / "a.yaml"), env=a.env, name="relay_a")
    relay_b = spawn(relay(tmp_path / "b.yaml"), env=b.env, name="relay_b")
    _stats_with(relay_a, "exports", "/reading")
    _stats_with(relay_b, "imports", "/robot_a/reading")

    listener = spawn(stock_listener("--topic", "/robot_a/reading", "--type", TYPE, "--definition", definition,
                                    "--count", 20, "--duration", 90), env=b.env)
    got = listener.wait_for_count("recv", 20, timeout=90)
    seqs = [int(e["msg"]["data"].split()[-1]) for e in got]
    assert seqs == list(range(seqs[0], seqs[0] + 20)), seqs           # in order, none lost
    assert all(e["msg"]["sample"]["value"] == float(s) for e, s in zip(got, seqs)), got[:2]  # the nested type
    assert all(e["msg"]["header"]["frame_id"] == "hello" and e["stamp"]["secs"] > 0 for e in got), got[:2]
    header = got[0]["connection_header"]
    assert header["type"] == TYPE and header["md5sum"] != "*", header  # B's relay publishes the real type
    chatter_b = _stats_with(relay_b, "imports", "/robot_a/reading")
    assert chatter_b["bad_input"] == 0 and chatter_b["refused"] == 0, chatter_b


def test_a_service_type_without_its_package_is_carried_as_bytes(
        robots: Tuple[harness.RosMaster, harness.RosMaster], spawn: harness.Spawner, tmp_path: Path) -> None:
    """``mrt_runtime/AddTwo`` exists in no package: a stock server in A and a stock client in B build it at run
    time; the relays, which cannot, forward the calls as bytes under the server's type and md5. A client with
    another definition of the type is refused by the server's md5 check, in words."""
    a, b = robots
    peer = str(harness.PEERS_DIR / "dyn_service.py")
    (tmp_path / "a.yaml").write_text("graph: robot_a\nexport_services: [/add_two]\n")
    (tmp_path / "b.yaml").write_text("graph: robot_b\nimport_services:\n  /robot_a/add_two: {timeout: 10}\n")
    server = spawn([harness.STOCK_PYTHON, peer, "server", "--seconds", "120"], env=a.env, name="add_two_server")
    server.wait_for("ready", 30)
    relay_a = spawn(relay(tmp_path / "a.yaml"), env=a.env, name="relay_a")
    relay_b = spawn(relay(tmp_path / "b.yaml"), env=b.env, name="relay_b")
    relay_a.wait_for(lambda e: e.get("event") == "stats" and bool(e.get("services")), 60)
    relay_b.wait_for(lambda e: e.get("event") == "stats" and bool(e.get("services")), 60)

    for x, y in ((2, 40), (-7, 1_000_000_000_000)):
        client = spawn([harness.STOCK_PYTHON, peer, "call", "--name", "/robot_a/add_two", "--a", str(x), "--b", str(y)],
                       env=b.env, name="add_two_client")
        assert client.wait(60) == 0, client.stderr_tail()
        answer = client.wait_for("response", 10)
        assert (answer["sum"], answer["note"]) == (x + y, f"robot A added {x} and {y}"), answer
    other = spawn([harness.STOCK_PYTHON, peer, "call", "--name", "/robot_a/add_two", "--other-definition"],
                  env=b.env, name="other_client")
    assert other.wait(60) == 1
    assert "md5sums do not match" in other.wait_for("error", 10)["text"]
    assert [(e["a"], e["b"]) for e in server.events("served")] == [(2, 40), (-7, 1_000_000_000_000)]
    # what B's rosservice sees: the real type and md5 (the relay announces what it forwards)
    info = subprocess.run(["/usr/bin/python3", "/usr/bin/rosservice", "type", "/robot_a/add_two"], env=b.env,
                          capture_output=True, text=True, timeout=60)
    assert info.stdout.strip() == "mrt_runtime/AddTwo", info
    last = relay_b.events("stats")[-1]["services"][0]
    assert (last["calls"], last["failed"]) == (2, 0), last
