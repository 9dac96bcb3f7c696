"""DirectQueuedConnection (issue 44): a micros_rt publication's TCPROS link writes a message at once when its
queue is idle, else through rospy's queue thread; the byte stream stays whole messages in order, whatever the
socket takes, and publish() never waits. Real rospy TCPROSTransport objects over a TCP connection on loopback."""

from __future__ import annotations

import socket
import struct
import threading
import time
from typing import Any, List, Tuple

from rospy.impl.tcpros_base import TCPROSTransport, TCPROSTransportProtocol

from micros_rt.transports.tcpros.patches import DirectQueuedConnection


def link(queue_size: int, *, sndbuf: int = 0) -> Tuple[DirectQueuedConnection, TCPROSTransport, socket.socket]:
    with socket.create_server(("127.0.0.1", 0)) as server:   # TCP on loopback, as TCPROS (partial writes happen)
        ours = socket.create_connection(server.getsockname())
        peer, _ = server.accept()
    if sndbuf:
        ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, sndbuf)
        peer.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, sndbuf)
    transport = TCPROSTransport(TCPROSTransportProtocol("/chatter", None), "/chatter")
    transport.set_socket(ours, "/listener")
    return DirectQueuedConnection(transport, queue_size), transport, peer


def frame(n: int, size: int) -> bytes:
    body = struct.pack("<I", n) + bytes([n % 251]) * (size - 4)
    return struct.pack("<I", len(body)) + body


def read_frames(peer: socket.socket, count: int, *, quiet: float = 10.0) -> List[int]:
    """The sequence numbers of the whole frames read from ``peer`` until ``count`` arrived, or frame ``count - 1``
    did, or nothing came for ``quiet`` seconds (AssertionError on a torn frame)."""
    peer.settimeout(quiet)
    data, seqs = b"", []  # type: Tuple[bytes, List[int]]
    while len(seqs) < count and not (seqs and seqs[-1] == count - 1):
        try:
            chunk = peer.recv(1 << 20)
        except (socket.timeout, TimeoutError):
            break
        assert chunk, f"the link closed after {len(seqs)} frames"
        data += chunk
        while len(data) >= 4:
            (length,) = struct.unpack_from("<I", data)
            if len(data) < 4 + length:
                break
            body, data = data[4:4 + length], data[4 + length:]
            (n,) = struct.unpack_from("<I", body)
            assert body[4:] == bytes([n % 251]) * (length - 4), f"frame {n} is torn"
            seqs.append(n)
    assert data == b"", f"{len(data)} bytes of a torn frame after frame {seqs[-1:]}"
    return seqs


def test_an_idle_link_is_written_from_the_publishing_thread() -> None:
    conn, transport, peer = link(1)
    try:
        writer_threads: List[str] = []
        original = transport.write_data

        def spy(data: Any) -> Any:   # the queue thread writes through the transport; the direct path does not
            writer_threads.append(threading.current_thread().name)
            return original(data)

        transport.write_data = spy
        for n in range(100):
            conn.write_data(frame(n, 64))
            assert transport.stat_num_msg == n + 1   # on the wire when write_data returned
        assert read_frames(peer, 100) == list(range(100))
        assert writer_threads == [] and transport.stat_bytes == 100 * 68
    finally:
        transport.close()
        peer.close()


def test_a_full_socket_queues_the_rest_and_the_stream_stays_whole_messages_in_order() -> None:
    conn, transport, peer = link(5, sndbuf=4096)
    try:
        t0 = time.monotonic()
        # nobody reads: the socket fills (one message is taken in part: frame 14 here, its rest queued and never
        # dropped), then rospy's queue keeps the newest 5
        for n in range(200):
            conn.write_data(frame(n, 3000))
        assert time.monotonic() - t0 < 5.0     # publish() never waited on the peer
        seqs = read_frames(peer, 200, quiet=3.0)
        # whole frames, in order, the last ones kept (the oldest queued ones dropped, as rospy's queue_size)
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs), seqs
        assert seqs[0] == 0 and seqs[-1] == 199 and len(seqs) < 200
    finally:
        transport.close()
        peer.close()
