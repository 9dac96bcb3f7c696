"""The link's QoS and bad-input handling, in-process on loopback sockets (no ROS node, no peers)."""

from __future__ import annotations

import socket
import time
from typing import Iterator, List, Tuple

import genpy
import pytest
from geometry_msgs.msg import Twist, TwistStamped
from std_msgs.msg import String

import harness
from micros_rt.transports.mcu import wire
from micros_rt.transports.mcu.config import McuConfig, parse_config
from micros_rt.transports.mcu.errors import DatagramTooLargeError
from micros_rt.transports.mcu.link import McuLink

BOARD = "127.0.0.2"


def free_udp_port(address: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((address, 0))
        return int(s.getsockname()[1])


@pytest.fixture
def board() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((BOARD, 0))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_RECVTOS, 1)
    sock.settimeout(2.0)
    try:
        yield sock
    finally:
        sock.close()


def config(board: socket.socket, body: str) -> McuConfig:
    port = board.getsockname()[1]
    return parse_config(f"microcontroller: {{address: {BOARD}, topic_port: {port}}}\n"
                        f"bind: {{address: 127.0.0.1, topic_port: {free_udp_port('127.0.0.1')}, "
                        f"service_port: {harness.free_tcp_port()}}}\n{body}", source="test.yaml")


def received(board: socket.socket) -> List[Tuple[bytes, int]]:
    """Every datagram the board has now, with its IP TOS."""
    out = []
    board.settimeout(0.3)
    try:
        while True:
            data, anc, _, _ = board.recvmsg(65536, socket.CMSG_SPACE(4))
            out.append((data, anc[0][2][0] if anc else -1))
    except socket.timeout:
        return out


def test_oversized_message_is_refused_with_topic_and_sizes(board: socket.socket) -> None:
    cfg = config(board, "mtu: 64\nto_microcontroller:\n  - {topic: /text, type: std_msgs/String, name: t}\n")
    with McuLink(cfg) as link:
        writer = link.open_writer(cfg.to_microcontroller[0])
        with pytest.raises(DatagramTooLargeError) as info:
            writer.prepare(String(data="x" * 100))
        assert "/text: the message encodes to 111 bytes, more than the microcontroller link's mtu of 64" \
            in str(info.value)
        assert writer.offer(String(data="x" * 100)) == "oversized"
        assert writer.offer(String(data="short")) == "sent"
        got = received(board)
        assert [d for d, _ in got] == [wire.encode_datagram("t", {"data": "short"})]  # never truncated
        assert link.stats.get("to_microcontroller", "oversized", entry="t") == 1


def test_transport_priority_sets_the_datagrams_tos(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /fast, type: geometry_msgs/Twist, name: fast, qos: {transport_priority: HIGH}}\n"
                        "  - {topic: /slow, type: geometry_msgs/Twist, name: slow}\n")
    with McuLink(cfg) as link:
        fast, slow = (link.open_writer(e) for e in cfg.to_microcontroller)
        fast.offer(Twist())
        slow.offer(Twist())
        tos = {wire.split_datagram(d)[0]: t for d, t in received(board)}
        assert tos == {"fast": 34 << 2, "slow": 0}  # HIGH is DSCP AF41 (34)


def test_msg_valid_period_drops_stale_stamped_messages(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /cmd, type: geometry_msgs/TwistStamped, name: c, qos: {msg_valid_period: 0.5}}\n")
    with McuLink(cfg) as link:
        writer = link.open_writer(cfg.to_microcontroller[0])
        stale, fresh = TwistStamped(), TwistStamped()
        stale.header.stamp = genpy.Time.from_sec(time.time() - 5.0)
        fresh.header.stamp = genpy.Time.from_sec(time.time())
        assert [writer.offer(stale), writer.offer(fresh)] == ["expired", "sent"]
        assert len(received(board)) == 1


def test_time_filter_limits_what_the_board_receives(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /cmd, type: geometry_msgs/Twist, name: c, qos: {time_filter_duration: 0.2}}\n")
    with McuLink(cfg) as link:
        writer = link.open_writer(cfg.to_microcontroller[0])
        outcomes = [writer.offer(Twist()) for _ in range(50)]
        assert outcomes[0] == "sent" and outcomes.count("sent") == 1 and outcomes.count("filtered") == 49
        time.sleep(0.25)
        assert writer.offer(Twist()) == "sent"


def test_bad_datagrams_are_counted_by_kind_and_the_next_good_one_arrives(board: socket.socket) -> None:
    cfg = config(board, "from_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twist, name: c}\n")
    woken: List[int] = []
    with McuLink(cfg) as link:
        reader = link.open_reader(cfg.from_microcontroller[0], lambda: woken.append(1))
        bridge = cfg.bind.topic()
        board.sendto(b"\xc1garbage", bridge)
        board.sendto(wire.encode_datagram("nobody", {}), bridge)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.bind(("127.0.0.3", 0))
            stranger.sendto(wire.encode_datagram("c", wire.codec_for(Twist).to_wire(Twist())), bridge)
        board.sendto(wire.encode_datagram("c", wire.codec_for(Twist).to_wire(Twist())), bridge)
        harness.wait_until(lambda: woken, 5.0, message="the good datagram")
        (payload, info), = reader.take(10)
        assert reader.decode(payload) == Twist() and info["source"].startswith(BOARD)
        assert link.stats.snapshot()["bad_input"] == {"not_msgpack": 1, "unknown_stream": 1, "foreign_sender": 1}
