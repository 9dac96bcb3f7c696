"""Every transport's (writer, reader) pair for the contract (:mod:`checks`), each on a topic of its own.

``fake`` (in memory), ``dds`` (Cyclone in this process, loopback config, this run's domain), ``mcu`` (the
microcontroller UDP link sending to itself on loopback), ``mqtt`` (two MQTT back ends of two graphs through a
real mosquitto: a back end ignores messages of its own graph), ``tcpros`` (rospy's transport; needs a node, so
only :mod:`tcpros_child` makes it).
"""

from __future__ import annotations

import itertools
import os
import socket
import time
from typing import Any, Callable, Dict, List, Optional

from geometry_msgs.msg import PointStamped

from micros_rt.qos import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.transports.base import EndpointSpec, PushReader, TransportReader, TransportWriter

from contract.checks import PROBE, Pair, message

__all__ = ["dds_pair", "fake_pair", "mcu_pair", "mqtt_pair", "shm_pair", "tcpros_pair"]

_n = itertools.count()


def _topic(kind: str) -> str:
    return f"/contract_{kind}_{os.getpid()}_{next(_n)}"


def fake_pair() -> Pair:
    from contract.fake_transport import FakeBus

    bus, topic = FakeBus(), _topic("fake")
    writer, reader = bus.writer(topic), bus.reader(topic, PointStamped)
    return Pair("fake", writer, reader, matched=lambda: bool(bus.readers(topic)),
                lonely_writer=lambda: bus.writer(_topic("fake_lonely")),
                corrupt=lambda: reader.decode_payload(b"\x01\x02\x03"))


def dds_pair() -> Pair:
    from micros_rt.transports.dds.backend import DDSBackend
    from micros_rt.transports.dds.participant import get_participant

    participant = get_participant()
    assert participant is not None, "no DDS participant (cyclonedds missing?)"
    backend = DDSBackend(participant, "contract")
    tag = {"graph": "contract", "node": "/contract"}
    spec = EndpointSpec(_topic("dds"), PointStamped, 10, False, tag)
    writer = backend.open_writer(spec, AdvertiseQoSOptions())
    reader = backend.open_reader(spec, None, lambda: None, lambda _policy: None)
    opened: List[Any] = []

    def lonely() -> TransportWriter:
        return backend.open_writer(EndpointSpec(_topic("dds_lonely"), PointStamped, 10, False, tag),
                                   AdvertiseQoSOptions())

    def filtering(period: float) -> TransportReader:
        r = backend.open_reader(spec, SubscribeQoSOptions(time_filter_duration=period), lambda: None, lambda _p: None)
        opened.append(r)
        from contract.checks import wait_until
        wait_until(lambda: len(writer.matched_peers()) >= 2, 20, "the filtering reader to match")
        return r

    def cleanup() -> None:
        for r in opened:
            r.close()

    return Pair("dds", writer, reader,
                matched=lambda: bool(writer.matched_peers()) and bool(reader.matched_writers()),
                lonely_writer=lonely, corrupt=lambda: reader.decode(b"\x00\x01\x00\x00\x07"),
                filtering_reader=filtering, cleanup=cleanup)


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def mcu_pair() -> Pair:
    """The link's writer sends to the link's own port (the "board" is the link itself, on loopback), so its
    reader hears what its writer sent, through the kernel, in the wire's own form."""
    from micros_rt.bridges.mcu.config import parse_config
    from micros_rt.transports.mcu.link import McuLink

    udp, tcp = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_STREAM)
    cfg = parse_config(f"microcontroller: {{address: 127.0.0.1, topic_port: {udp}, service_port: {tcp}}}\n"
                       f"bind: {{address: 127.0.0.1, topic_port: {udp}, service_port: {tcp}}}\n"
                       f"to_microcontroller:\n  - {{topic: /contract_mcu_out, type: geometry_msgs/PointStamped, name: p}}\n"
                       f"from_microcontroller:\n  - {{topic: /contract_mcu_in, type: geometry_msgs/PointStamped, name: p}}\n",
                       source="contract.yaml")
    link = McuLink(cfg)
    writer = link.open_writer(cfg.to_microcontroller[0])
    reader = link.open_reader(cfg.from_microcontroller[0], 100)
    return Pair("mcu", writer, reader, matched=lambda: True, lonely_writer=None,
                corrupt=lambda: reader.decode_datagram(b"\xc1garbage"), cleanup=link.close)


class MqttFeed(PushReader):
    """What a subscription makes of an MQTT feed: a pushed reader that the back end's reader delivers to."""

    feed: Any = None

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
            self.feed = None
        super().close()


def mqtt_pair(broker_port: int) -> Pair:
    from micros_rt.transports.mqtt import codec
    from micros_rt.transports.mqtt.backend import MqttBackend, parse_mqtt_section

    topic = _topic("mqtt")

    def backend(graph: str) -> MqttBackend:
        section: Dict[str, Any] = {"broker": {"host": "127.0.0.1", "port": broker_port},
                                   "client": {"id": f"contract_{graph}_{os.getpid()}"}, "topics": {topic: {}}}
        return MqttBackend(parse_mqtt_section(section, source="contract"), graph=graph, node="/contract")

    out, into = backend("contract_out"), backend("contract_in")
    spec = EndpointSpec(topic, PointStamped, 10, False, {"graph": "contract_out", "node": "/contract"})
    writer = out.open_writer(spec, AdvertiseQoSOptions())
    assert writer is not None
    reader = MqttFeed("MQTT", 100, lambda: None, blocking=False)
    reader.feed = into.open_feed(spec, None, reader.put)
    probe = message(0)
    probe.header.frame_id = PROBE

    def matched() -> bool:  # the broker says nothing about subscribers: a probe that arrives is the proof
        if any(m.header.frame_id == PROBE for m, _ in list(reader._queue)):
            return True
        prepared = writer.prepare(probe)
        writer.send(prepared)
        return False

    def cleanup() -> None:
        out.close()
        into.close()

    return Pair("mqtt", writer, reader, matched=matched, lonely_writer=None,
                corrupt=lambda: codec.decode_ros_payload(b"\x01", stamped=None), cleanup=cleanup)


def tcpros_pair(topic: Optional[str] = None) -> Pair:
    """rospy's TCPROS (micros_rt's TcprosWriter/TcprosReader) in this node, which must be initialised."""
    from micros_rt.transports.tcpros import TcprosReader, TcprosWriter
    from micros_rt.negotiation import TCPROS

    topic = topic or _topic("tcpros")
    writer = TcprosWriter(topic, PointStamped, 10, False, pseudo_links=lambda: 0)
    reader = PushReader(TCPROS, 100, lambda: None, blocking=True)
    sub = TcprosReader(topic, PointStamped, reader.put, 100)
    reader_close = reader.close

    def close() -> None:
        sub.close()
        reader_close()

    reader.close = close  # type: ignore[method-assign]
    lonely: Callable[[], TransportWriter] = lambda: TcprosWriter(_topic("tcpros_lonely"), PointStamped, 10,
                                                                        False, pseudo_links=lambda: 0)

    def corrupt() -> None:  # rospy's receive thread decodes TCPROS: what micros_rt adds is its own codec check
        raise AssertionError("unused")

    return Pair("tcpros", writer, reader, matched=lambda: writer.links() > 0 and bool(sub.transports()),
                lonely_writer=lonely, corrupt=corrupt)


def shm_pair() -> Pair:
    """Shared memory: a publication's writer with a channel for one subscriber, and that subscriber's link
    feeding a pushed reader (what a subscription makes of it), in this process."""
    from micros_rt.transports.shm import channel as shm
    from micros_rt.transports.shm import host

    was = os.environ.get("MICROS_RT_DISABLE_SHM")
    os.environ["MICROS_RT_DISABLE_SHM"] = "0"  # the suite keeps SHM off for its other nodes (tests/harness.py)
    try:
        host.shm_node()
    finally:
        if was is None:
            os.environ.pop("MICROS_RT_DISABLE_SHM", None)
        else:
            os.environ["MICROS_RT_DISABLE_SHM"] = was
    topic = _topic("shm")
    writer = shm.ShmWriter(topic, lossless=False, latch=False)
    channel = writer.open_channel("/contract_subscriber")
    reader = PushReader("SHM", 100, lambda: None, blocking=True)
    header = {"callerid": "/contract", "topic": topic, "type": PointStamped._type, "md5sum": PointStamped._md5sum,
              "transport": "SHM"}
    link = shm.ShmLink(topic, channel.name, PointStamped, header=header, qos=None, put=reader.put,
                       on_drop=lambda n: None, on_gone=lambda _link: None)
    link.start_thread()  # pushed, as beside a DDS reader (a subscription without one polls it: integration tests)

    def cleanup() -> None:
        link.close()

    def send_stale(msg: PointStamped, age: float) -> None:
        body = writer.prepare(msg)
        assert body is not None and channel.try_send(body, source_ns=time.time_ns() - int(age * 1e9))

    return Pair("shm", writer, reader, matched=channel.attached, send_stale=send_stale,
                lonely_writer=lambda: shm.ShmWriter(_topic("shm_lonely"), lossless=False, latch=False),
                corrupt=lambda: shm.decode_frame(PointStamped, b"\x01" * 16 + b"\x05\x00"), cleanup=cleanup)
