"""Links of limited bandwidth in a profile (qos/links.py) and TCP pacing of the connections across them
(transports/pacing.py), on real loopback TCP sockets."""

from __future__ import annotations

import socket
from typing import Iterator, Tuple

import pytest

from micros_rt.exceptions import ProfileError
from micros_rt.qos import QoSProfile, TransportPriority
from micros_rt.qos.links import LinkSpec, parse_bandwidth, parse_link
from micros_rt.transports.netif import interface_of
from micros_rt.transports.pacing import LinkPacer, pacing_rate, set_pacing_rate, share_out


@pytest.mark.parametrize("text, bits", [("40Mbit", 40e6), ("40 Mbit/s", 40e6), ("40mbps", 40e6),
                                        ("500kbit", 5e5), ("1Gbit", 1e9), (5000000, 5e6), ("2.5 Mbits/s", 2.5e6)])
def test_bandwidths_in_bits_per_second(text: object, bits: float) -> None:
    assert parse_bandwidth(text) == bits


@pytest.mark.parametrize("text", ["40MB", "40 MB/s", "fast", "0", "-3Mbit", True, ".inf"])
def test_what_is_not_a_bandwidth_is_refused(text: object) -> None:
    with pytest.raises(ValueError, match="bandwidth"):
        parse_bandwidth(text)


def test_a_profile_names_a_link_by_peers_or_interface() -> None:
    profile = QoSProfile.from_string("links:\n  radio: {peers: [10.0.0.0/24, 10.1.0.7], bandwidth: 40Mbit}\n"
                                     "  wifi: {interface: wlan0, bandwidth: 20Mbit, reserve: 0.25}\n")
    radio, wifi = profile.links
    assert radio.reaches("10.0.0.9", None) and radio.reaches("10.1.0.7", None)
    assert radio.reaches("::ffff:10.0.0.9", None)        # an IPv4 peer on a dual-stack socket
    assert not radio.reaches("10.1.0.8", None) and not radio.reaches("127.0.0.1", "wlan0")
    assert radio.paced_rate == 36e6 and wifi.paced_rate == 15e6
    assert wifi.reaches("10.9.9.9", "wlan0") and not wifi.reaches("10.0.0.9", "eth0")


@pytest.mark.parametrize("body, message", [
    ("{peers: [10.0.0.0/24]}", "q.yaml:2: links.radio.bandwidth: missing"),
    ("{peers: [10.0.0.0/24], bandwidth: 40MB}", "q.yaml:2: links.radio.bandwidth: '40MB' is not a bandwidth"),
    ("{bandwidth: 1Mbit}", "q.yaml:2: links.radio: give either peers"),
    ("{peers: [x], interface: wlan0, bandwidth: 1Mbit}", "q.yaml:2: links.radio: give either peers"),
    ("{peers: [10.0.0.300], bandwidth: 1Mbit}", "q.yaml:2: links.radio.peers: "),
    ("{peers: [], bandwidth: 1Mbit}", "q.yaml:2: links.radio.peers: expected a list"),
    ("{interface: wlan0, bandwidth: 1Mbit, reserve: 1.0}", "q.yaml:2: links.radio.reserve: expected the share"),
    ("{interface: wlan0, bandwidth: 1Mbit, rate: 3}", "q.yaml:2: links.radio.rate: unknown key"),
    ("3", "q.yaml:2: links.radio: expected a mapping"),
])
def test_a_bad_link_is_one_line_naming_file_line_and_key(body: str, message: str) -> None:
    with pytest.raises(ProfileError) as err:
        QoSProfile.from_string(f"links:\n  radio: {body}\n", source="q.yaml")
    assert str(err.value).startswith(message), str(err.value)


def test_max_min_fair_shares() -> None:
    assert share_out(30.0, [1.0, 100.0, 100.0]) == [1.0, 14.5, 14.5]
    assert share_out(30.0, [5.0, 5.0]) == [15.0, 15.0]            # what nobody asks for is split equally
    assert sum(share_out(10.0, [100.0, 3.0, 100.0, 1.0])) == pytest.approx(10.0)


@pytest.fixture
def tcp_pair() -> Iterator[Tuple[socket.socket, socket.socket]]:
    server = socket.create_server(("127.0.0.1", 0))
    client = socket.create_connection(server.getsockname())
    accepted, _ = server.accept()
    server.close()
    try:
        yield accepted, client
    finally:
        accepted.close()
        client.close()


def test_the_kernel_takes_a_pacing_rate(tcp_pair: Tuple[socket.socket, socket.socket]) -> None:
    sock, _ = tcp_pair
    assert pacing_rate(sock) is None
    set_pacing_rate(sock, 4.5e6)
    assert pacing_rate(sock) == 4_500_000
    set_pacing_rate(sock, None)
    assert pacing_rate(sock) is None


def test_below_high_across_a_link_is_paced_high_and_other_peers_are_not(
        tcp_pair: Tuple[socket.socket, socket.socket]) -> None:
    sock, _ = tcp_pair
    elsewhere = LinkPacer([parse_link("radio", {"peers": ["10.0.0.0/24"], "bandwidth": "40Mbit"})])
    assert elsewhere.attach(sock, "/image", TransportPriority.LOW) is None and pacing_rate(sock) is None
    pacer = LinkPacer([parse_link("radio", {"peers": ["127.0.0.0/8"], "bandwidth": "40Mbit"})])
    assert pacer.attach(sock, "/control", TransportPriority.HIGH) is None and pacing_rate(sock) is None
    said = pacer.attach(sock, "/image", TransportPriority.LOW)
    assert said is not None and "36 Mbit/s" in said and "link radio" in said
    assert pacing_rate(sock) == 36_000_000 // 8
    (link,) = pacer.snapshot()
    assert link["connections"] == [{"topic": "/image", "peer": "127.0.0.1", "rate_bps": 36e6, "used_bps": 0.0}]


def test_connections_on_one_link_share_it_and_a_closed_one_leaves_its_share(
        tcp_pair: Tuple[socket.socket, socket.socket]) -> None:
    first, _ = tcp_pair
    pacer = LinkPacer([LinkSpec("lo", 80e6, interface="lo", reserve=0.5)])
    assert interface_of("127.0.0.1") == "lo"
    pacer.attach(first, "/a", TransportPriority.NORMAL)
    assert pacing_rate(first) == 5_000_000                  # 40 of 80 Mbit/s for topics below HIGH
    server = socket.create_server(("127.0.0.1", 0))
    with socket.create_connection(server.getsockname()):
        second, _ = server.accept()
        server.close()
        pacer.attach(second, "/b", TransportPriority.LOW)
        # two connections: the link's 40 Mbit/s split between them, never more than it in all
        assert (pacing_rate(first) or 0) + (pacing_rate(second) or 0) <= 5_000_000
        assert (pacing_rate(second) or 0) >= 2_500_000      # the new one may have at least an equal share
        second.close()
    pacer.rebalance()   # a quiet connection alone on the link has all of it again
    assert [c["topic"] for c in pacer.snapshot()[0]["connections"]] == ["/a"]
    assert pacing_rate(first) == 5_000_000
