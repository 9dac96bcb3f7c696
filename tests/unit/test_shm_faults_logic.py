"""Shared memory's checks of what it is told (issue 46): frames and offers not believed until checked."""

from __future__ import annotations

import io
import struct
import time
from typing import Any, Dict, List, Tuple

import pytest
from std_msgs.msg import String

from micros_rt.transports.shm.channel import MAX_SEQ_GAP, MalformedFrameError, decode_frame
from micros_rt.transports.shm.vetting import OfferVetting


def frame(seq: int, msg: Any, cut: int = 0) -> bytes:
    buff = io.BytesIO()
    msg.serialize(buff)
    body = buff.getvalue()
    return struct.pack("<QQ", seq, 5) + (body[:-cut] if cut else body)


def test_a_frame_is_decoded_with_its_number_and_time() -> None:
    seq, ns, msg = decode_frame(String, frame(1, String(data="hello")))
    assert (seq, ns, msg.data) == (1, 5, "hello")


def test_a_truncated_frame_is_malformed_not_a_shorter_string() -> None:
    with pytest.raises(MalformedFrameError, match="length fields need 15 bytes, the frame holds 9"):
        decode_frame(String, frame(1, String(data="hello world"), cut=6))


@pytest.mark.parametrize("seq,last", [(2 ** 64 - 1, 0), (MAX_SEQ_GAP + 8, 7), (7, 7), (3, 7), (0, 0)])
def test_a_number_that_does_not_follow_the_channels_is_malformed(seq: int, last: int) -> None:
    with pytest.raises(MalformedFrameError, match=f"numbered {seq} follows number {last}"):
        decode_frame(String, frame(seq, String(data="x")), last)


def test_a_gap_within_the_bound_is_believed() -> None:
    assert decode_frame(String, frame(MAX_SEQ_GAP + 7, String(data="x")), 7)[0] == MAX_SEQ_GAP + 7


class FakeGraph:
    """The master's lookupNode and each node's getPid, as the vetting asks them."""

    def __init__(self, nodes: Dict[str, Tuple[str, int]]) -> None:
        self.nodes = nodes
        self.calls: List[Tuple[str, str]] = []

    def ask(self, uri: str, method: str, *args: Any) -> Any:
        self.calls.append((uri, method))
        if method == "lookupNode":
            if args[0] not in self.nodes:
                raise LookupError(f"unknown node [{args[0]}]")
            return self.nodes[args[0]][0]
        return next(pid for u, pid in self.nodes.values() if u == uri)


def vetting(graph: FakeGraph) -> OfferVetting:
    return OfferVetting(master_uri=lambda: "http://master:1/", ask=graph.ask)


def test_an_offer_from_the_named_nodes_process_is_believed_and_remembered() -> None:
    graph = FakeGraph({"/listener": ("http://l:2/", 4242)})
    v = vetting(graph)
    assert v.why_not("/listener", 4242) is None
    assert v.why_not("/listener", 4242) is None
    assert len(graph.calls) == 2  # asked once


@pytest.mark.parametrize("caller,pid,words", [
    ("/listener", 0, "names no process (pid 0)"),
    ("/listener", 999, "names process 999, but node /listener (registered at http://l:2/) runs as process 4242"),
    ("/forged_17", 4242, "/forged_17 is not a node registered with the ROS master (unknown node [/forged_17])"),
])
def test_an_offer_the_graph_does_not_confirm_is_refused_in_words(caller: str, pid: int, words: str) -> None:
    reason = vetting(FakeGraph({"/listener": ("http://l:2/", 4242)})).why_not(caller, pid)
    assert reason is not None and words in reason


def test_an_unreachable_master_refuses_in_words() -> None:
    def ask(uri: str, method: str, *args: Any) -> Any:
        raise ConnectionRefusedError(111, "Connection refused")

    reason = OfferVetting(master_uri=lambda: "http://master:1/", ask=ask).why_not("/listener", 4242)
    assert reason is not None and reason.startswith("the ROS master did not say where /listener runs")


def test_a_directory_of_another_user_is_named_as_a_permission_problem(tmp_path: Any) -> None:
    import os
    import pwd

    from micros_rt.transports.shm.host import permission_problem

    root = tmp_path / "iox"
    (root / "services").mkdir(parents=True)
    assert permission_problem(f"{root}/") is None
    if os.geteuid() != 0:
        pytest.fail("this test gives a directory to another user: it needs root (the suite runs as root, README)")
    nobody = pwd.getpwnam("nobody").pw_uid
    os.chown(root / "services", nobody, nobody)
    os.chmod(root / "services", 0o750)
    reason = permission_problem(f"{root}/")
    assert reason is not None
    assert f"{root}/services belongs to uid {nobody} with mode 0750" in reason
    assert "a permission problem, not a full /dev/shm" in reason


def test_a_node_keeping_its_shared_memory_elsewhere_is_declined_in_words() -> None:
    from micros_rt.negotiation import PublicationFacts
    from micros_rt.transports.shm.offer import ShmOffer, decide_shm
    from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions

    facts = PublicationFacts("/chatter", "", None, "std_msgs/String", "992c", AdvertiseQoSOptions(), latch=False)
    older = ShmOffer("boot/net/mnt/0", "992c", "std_msgs/String", SubscribeQoSOptions())  # before issue 46
    verdict = decide_shm(older, facts, host="boot/net/mnt/0/u", unavailable=None, subscriber="/l")
    assert not verdict.accepted and "another micros_rt version" in verdict.reason
    other_user = ShmOffer("boot/net/mnt/1000/u", "992c", "std_msgs/String", SubscribeQoSOptions())
    assert "another Unix user" in decide_shm(other_user, facts, host="boot/net/mnt/0/u", unavailable=None,
                                             subscriber="/l").reason


def test_a_peer_process_is_dead_once_it_exited_even_unreaped_and_never_by_a_reused_pid() -> None:
    # channels and links ask each housekeeping tick whether their peer runs: a pidfd, one poll, no /proc read
    import os
    import signal
    import subprocess

    from micros_rt.transports.shm.host import PeerProcess, process_alive

    fds_before = len(os.listdir("/proc/self/fd"))
    child = subprocess.Popen(["sleep", "60"])
    peer = PeerProcess(child.pid)
    try:
        assert peer.alive() and peer.alive()
        assert peer._fd >= 0  # the pidfd, not the /proc fallback (Linux 5.3+, as Debian 12's 6.1)
        os.kill(child.pid, signal.SIGKILL)
        deadline = time.monotonic() + 10
        while peer.alive() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not peer.alive()  # a zombie (not reaped yet) is dead for us
        assert not process_alive(child.pid)  # as the fallback says
        child.wait()
        assert not peer.alive()  # and stays dead: the pid may be reused now
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        peer.close()
    assert PeerProcess(0).alive()  # unknown: alive
    gone = PeerProcess(child.pid)  # reaped before it was asked about
    assert not gone.alive()
    mine = PeerProcess(os.getpid())
    assert mine.alive() and mine._fd >= 0
    mine.close()  # closed: its descriptor let go, then asked the slow way, still right
    assert mine._fd < 0 and mine.alive() and mine._fd < 0
    assert len(os.listdir("/proc/self/fd")) == fds_before  # no descriptor left behind
