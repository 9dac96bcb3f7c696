"""A toy negotiated transport, whole: ``TOY`` carries a topic between a publisher and a subscriber of one process
through an in-process bus, negotiated in ``requestTopic`` exactly as shared memory and DDS are.

Plugging it in is this module plus one call, ``micros_rt.extend.register_negotiated_transport(TOY_TRANSPORT)``;
no file of micros_rt changes, and it imports nothing of micros_rt but :mod:`micros_rt.extend`. Its two sides follow
:mod:`micros_rt.transports.negotiated`: the publication's judges an offer (same process: accepted, a channel of its
own; else declined in words, and the subscriber's next protocol is tried), keeps the links in rospy's connection lists and gives ``publish()`` one more writer; the
subscription's offers, reads the answer and connects a channel whose messages go through the core's one
admission path (time filter, lifespan, queue_size, statistics) like every transport's.
"""

from __future__ import annotations

import io
import os
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from micros_rt.extend import (UNBOUNDED_QUEUE_DEPTH, MalformedNegotiationError, NegotiatedTransport, OfferJudge,
                              PseudoLink, PublicationHost, PublicationSide, PushReader, SubscriptionHost,
                              SubscriptionSide, Verdict, add_link, attach_link)

TOY = "TOY"

#: channel name -> the subscriber's callback, ``(serialized message, sending time ns)``
_BUS: Dict[str, Callable[[bytes, int], None]] = {}
_BUS_LOCK = threading.Lock()


class _Answer:
    def __init__(self, channel: str) -> None:
        self.channel = channel

    def to_xmlrpc(self) -> List[Any]:
        return [TOY, {"channel": self.channel}]


class _Writer:
    """What ``publish()`` sends through: every channel of the publication."""

    protocol = TOY

    def __init__(self, side: "ToyPublication") -> None:
        self._side = side

    def prepare(self, msg: Any) -> Optional[bytes]:
        if not self._side.links:
            return None  # nobody to send to on this transport
        buf = io.BytesIO()
        msg.serialize(buf)
        return buf.getvalue()

    def send(self, data: bytes) -> None:
        sent = time.time_ns()
        with _BUS_LOCK:
            deliver = [_BUS.get(conn.peer_guid) for conn in self._side.links.values()]
        for put in deliver:
            if put is not None:
                put(data, sent)

    def close(self) -> None:
        pass


class ToyPublication(PublicationSide):
    protocol = TOY

    def __init__(self, host: PublicationHost, refusal: Optional[Verdict]) -> None:
        super().__init__(host, refusal=refusal)
        self.links: Dict[str, PseudoLink] = {}  # subscriber caller id -> link

    def negotiated(self, subscriber: str) -> Optional[OfferJudge]:
        if self.refusal is not None:
            return None
        return OfferJudge(parse=_read_offer, judge=lambda pid: self._judge(pid, subscriber))

    def _judge(self, pid: int, subscriber: str) -> Tuple[Verdict, Optional[_Answer]]:
        host = self.host
        if pid != os.getpid():
            verdict = Verdict(False, "toy-process", f"topic {host.topic}: {subscriber} is process {pid}, the toy bus "
                                                    f"reaches only process {os.getpid()}")
            host.remember(subscriber, verdict)
            return verdict, None
        channel = f"{host.topic}#{subscriber}"
        conn = PseudoLink(host.topic, subscriber, "o", f"TOY connection on channel {channel}",
                                    peer_guid=channel, on_close=self._closed, transport=TOY)
        old = self.links.get(subscriber)
        self.links[subscriber] = conn
        refused = attach_link(host.topic, old, conn, what=TOY, subscriber=subscriber, fallback="the next")
        if refused is not None:
            return refused, None
        verdict = Verdict(True, "toy", f"topic {host.topic}: same process")
        host.remember(subscriber, verdict)
        if self.writer is None:
            self.writer = _Writer(self)
            host.writers_changed()
        return verdict, _Answer(channel)

    def _closed(self, conn: PseudoLink) -> None:
        if self.links.get(conn.endpoint_id) is conn:
            del self.links[conn.endpoint_id]

    def pseudo_links(self) -> int:
        return len(self.links)

    def reached(self) -> int:
        with _BUS_LOCK:
            return sum(1 for conn in self.links.values() if conn.peer_guid in _BUS)

    def close(self) -> None:
        for conn in list(self.links.values()):
            conn.close()


def _read_offer(params: Any, source: str) -> int:
    if not isinstance(params, dict) or not isinstance(params.get("pid"), int):
        raise MalformedNegotiationError("pid", f"a TOY offer from {source} names no process")
    return int(params["pid"])


class ToySubscription(SubscriptionSide):
    protocol = TOY
    words = "the toy bus"

    def __init__(self, host: SubscriptionHost) -> None:
        super().__init__(host)
        self.inlet = PushReader(TOY, host.depth or UNBOUNDED_QUEUE_DEPTH, host.wake, blocking=True)

    def offer(self, held: str) -> Optional[List[Any]]:
        return [TOY, {"pid": os.getpid()}]

    def read_answer(self, params: Any, source: str) -> str:
        if not isinstance(params, dict) or not isinstance(params.get("channel"), str):
            raise MalformedNegotiationError("channel", f"a TOY answer from {source} names no channel")
        return str(params["channel"])

    def peer_of(self, answer: Any) -> str:
        return str(answer)

    def pushed(self) -> Tuple[PushReader, ...]:
        return (self.inlet,)

    def connect(self, pub_uri: str, answer: Any) -> Tuple[int, str, int]:
        host = self.host
        header = {"callerid": pub_uri, "topic": host.topic, "type": host.data_class._type,
                  "md5sum": host.data_class._md5sum, "transport": TOY}

        def put(data: bytes, sent_ns: int) -> None:
            msg = host.data_class()
            msg.deserialize(data)
            msg._connection_header = header
            self.inlet.put(msg, sent_ns)

        def closed(_conn: PseudoLink) -> None:
            with _BUS_LOCK:
                _BUS.pop(answer, None)

        conn = PseudoLink(host.topic, pub_uri, "i", f"TOY connection on channel {answer}",
                                    peer_guid=answer, on_close=closed, transport=TOY)
        with _BUS_LOCK:
            _BUS[answer] = put
        if not add_link(host.topic, conn, publisher=False):
            conn.close()
            return 0, "subscriber closed", 0
        host.wake()
        return 1, f"Connected topic[{host.topic}] over TOY", 0


TOY_TRANSPORT = NegotiatedTransport(TOY, ToyPublication, ToySubscription)
