"""The link's wire behaviour and bad-input handling, and the core's QoS on both directions of the bridge,
in-process on loopback sockets (no ROS node, no peers)."""

from __future__ import annotations

import dataclasses
import functools
import math
import socket
import time
from typing import Any, Callable, Iterator, List, Tuple

import genpy
import pytest
from geometry_msgs.msg import Twist, TwistStamped
from std_msgs.msg import String

import harness
from micros_rt import SubscribeQoSOptions, TransportError
from micros_rt.transports.mcu import wire
from micros_rt.bridges.mcu.config import parse_config
from micros_rt.transports.mcu.spec import McuConfig
from micros_rt.transports.mcu.errors import DatagramTooLargeError
from micros_rt.transports.mcu.link import McuLink, UdpWriter

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


def _send(writer: UdpWriter, msg: Any) -> str:
    """What the bridge's subscription callback does (bridges/mcu/bridge.py): prepare, then send."""
    try:
        writer.send(writer.prepare(msg))
    except DatagramTooLargeError:
        return "oversized"
    return "sent"


def _subscription(options: SubscribeQoSOptions, callback: Callable[[Any], None], *,
                  lifespan: float = math.inf) -> Any:
    """A micros_rt subscription as ``subscribe_with_qos`` makes it, delivery thread only (no master):
    what ROS publishers send arrives through its TCPROS reader (``tcp_in``)."""
    from micros_rt.core.subscription import _Subscription
    from micros_rt.negotiation import TransportHints

    sub = _Subscription("/cmd", TwistStamped, 100, options, TransportHints().tcp(), tag={}, graph="g")
    sub.lifespan = lifespan
    sub.callbacks = ((callback, None),)
    sub.thread.start()
    return sub


def test_oversized_message_is_refused_with_topic_and_sizes(board: socket.socket) -> None:
    cfg = config(board, "mtu: 64\nto_microcontroller:\n  - {topic: /text, type: std_msgs/String, name: t}\n")
    with McuLink(cfg) as link:
        writer = link.open_writer(cfg.to_microcontroller[0])
        with pytest.raises(DatagramTooLargeError) as info:
            writer.prepare(String(data="x" * 100))
        # [t, "x" * 100] in CVRA's final form: 92, a1 74, d9 64, 100 bytes (the map form was 111)
        assert "/text: the message encodes to 105 bytes, more than the microcontroller link's mtu of 64" \
            in str(info.value)
        assert _send(writer, String(data="x" * 100)) == "oversized"
        assert _send(writer, String(data="short")) == "sent"
        got = received(board)
        assert [d for d, _ in got] == [wire.encode_datagram("t", {"data": "short"})]  # never truncated
        assert link.stats.snapshot()["to_microcontroller"]["t"] == {"sent": 1, "oversized": 2, "send_failed": 0}


def test_a_closed_writer_refuses_in_words_and_counts_it(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n  - {topic: /text, type: std_msgs/String, name: t}\n")
    with McuLink(cfg) as link:
        writer = link.open_writer(cfg.to_microcontroller[0])
        data = writer.prepare(String(data="late"))
        writer.close()
        writer.close()
        with pytest.raises(TransportError, match="the writer of /text is closed"):
            writer.send(data)
        assert received(board) == []


def test_transport_priority_sets_the_datagrams_tos(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /fast, type: geometry_msgs/Twist, name: fast, qos: {transport_priority: HIGH}}\n"
                        "  - {topic: /slow, type: geometry_msgs/Twist, name: slow}\n")
    with McuLink(cfg) as link:
        fast, slow = (link.open_writer(e) for e in cfg.to_microcontroller)
        _send(fast, Twist())
        _send(slow, Twist())
        tos = {wire.split_datagram(d)[0]: t for d, t in received(board)}
        assert tos == {"fast": 34 << 2, "slow": 0}  # HIGH is DSCP AF41 (34)


def test_msg_valid_period_drops_stale_stamped_messages_before_the_board(board: socket.socket) -> None:
    """The entry's msg_valid_period is applied by the core's subscription (the bridge passes it to
    subscribe_with_qos), judged by the Header stamp of what arrives over TCPROS; the link only sends."""
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /cmd, type: geometry_msgs/TwistStamped, name: c, qos: {msg_valid_period: 0.5}}\n")
    entry = cfg.to_microcontroller[0]
    with McuLink(cfg) as link:
        writer = link.open_writer(entry)
        sub = _subscription(SubscribeQoSOptions(ordered_by_sending_timestamp=False), lambda m: None if _send(writer, m) else None,
                            lifespan=entry.advertise.msg_valid_period)
        try:
            stale, fresh = TwistStamped(), TwistStamped()
            stale.header.stamp = genpy.Time.from_sec(time.time() - 5.0)
            stale.header.frame_id = "stale"
            fresh.header.stamp = genpy.Time.from_sec(time.time())
            fresh.header.frame_id = "fresh"
            sub.tcp_in.put(stale)
            sub.tcp_in.put(fresh)
            harness.wait_until(lambda: sub.statistics().delivered == 1, 10, message="the fresh one delivered")
            got = received(board)
            assert [wire.codec_for(TwistStamped).from_args(wire.split_datagram(d)[1]).header.frame_id
                    for d, _ in got] == ["fresh"]
            stats = sub.statistics()
            assert (stats.received, stats.dropped_expired) == (2, 1)
            assert link.stats.get("to_microcontroller", "sent", entry="c") == 1
        finally:
            sub.close()


def test_time_filter_limits_what_the_board_receives(board: socket.socket) -> None:
    cfg = config(board, "to_microcontroller:\n"
                        "  - {topic: /cmd, type: geometry_msgs/TwistStamped, name: c,"
                        " qos: {time_filter_duration: 0.2}}\n")
    entry = cfg.to_microcontroller[0]
    with McuLink(cfg) as link:
        writer = link.open_writer(entry)
        options = SubscribeQoSOptions(ordered_by_sending_timestamp=False,
                                      time_filter_duration=entry.subscribe.time_filter_duration)
        sub = _subscription(options, lambda m: None if _send(writer, m) else None)
        try:
            for _ in range(50):
                sub.tcp_in.put(TwistStamped())
            harness.wait_until(lambda: sub.statistics().received == 50, 10, message="fifty taken")
            assert (sub.statistics().delivered, sub.statistics().dropped_filtered) == (1, 49)
            assert len(received(board)) == 1
            time.sleep(0.25)  # past the filter's period (a duration under test, not a wait for an event)
            sub.tcp_in.put(TwistStamped())
            harness.wait_until(lambda: sub.statistics().delivered == 2, 10, message="the next period's one")
            assert len(received(board)) == 1
        finally:
            sub.close()


def test_bad_datagrams_are_counted_by_kind_and_the_next_good_one_arrives(board: socket.socket) -> None:
    cfg = config(board, "from_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twist, name: c}\n")
    woken: List[int] = []
    with McuLink(cfg) as link:
        reader = link.open_reader(cfg.from_microcontroller[0], 10, lambda: woken.append(1))
        bridge = cfg.bind.topic()
        board.sendto(b"\xc1garbage", bridge)
        board.sendto(wire.encode_datagram("nobody", {}), bridge)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.bind(("127.0.0.3", 0))
            stranger.sendto(wire.encode_datagram("c", wire.codec_for(Twist).to_wire(Twist())), bridge)
        board.sendto(wire.encode_datagram("c", {"linear": {"x": 1}}), bridge)  # missing fields
        board.sendto(wire.encode_datagram("c", wire.codec_for(Twist).to_wire(Twist())), bridge)
        harness.wait_until(lambda: woken, 5.0, message="the good datagram")
        (msg, info), = reader.take(10)
        assert reader.decode(msg) == Twist() and info.publication_handle.startswith(BOARD)
        assert link.stats.snapshot()["bad_input"] == {"not_msgpack": 1, "unknown_stream": 1, "foreign_sender": 1,
                                                      "missing_field": 1}
        assert reader.transports() == {f"udp://{BOARD}:{board.getsockname()[1]}/c": "MCU-UDP"}


def test_board_streams_go_through_the_cores_time_filter_and_deadline(board: socket.socket) -> None:
    """board -> ROS as the bridge runs it: the link's reader feeds a ReaderSubscription (what
    NodeHandle.subscribe_reader makes); the core filters, watches the deadline and counts."""
    from micros_rt.core.reader_subscription import ReaderSubscription

    cfg = config(board, "from_microcontroller:\n  - {topic: /twist, type: geometry_msgs/Twist, name: tw,"
                        " qos: {time_filter_duration: 30, deadline: 0.2}}\n")
    entry = cfg.from_microcontroller[0]
    got: List[Any] = []
    misses: List[Any] = []
    with McuLink(cfg) as link:
        options = dataclasses.replace(entry.subscribe, deadline_cb=misses.append)
        sub = ReaderSubscription(entry.topic, entry.data_class, functools.partial(link.open_reader, entry), 100,
                                 options, graph="g")
        sub.callbacks = ((got.append, None),)
        sub.start()
        try:
            harness.wait_until(lambda: misses, 10, message="a deadline miss while the board is silent")
            datagram = wire.encode_datagram("tw", wire.codec_for(Twist).to_wire(Twist()))
            for _ in range(20):
                board.sendto(datagram, cfg.bind.topic())
            harness.wait_until(lambda: sub.statistics().received == 20, 10, message="twenty datagrams taken")
            stats = sub.statistics()
            assert got == [Twist()] and (stats.delivered, stats.dropped_filtered) == (1, 19)
            assert misses[0].topic == "/twist" and misses[0].deadline == 0.2 and stats.deadline_missed >= 1
        finally:
            sub.close()
