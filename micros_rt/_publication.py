"""A micros_rt publication: per topic and process, the rospy publisher and the DDS writer."""

from __future__ import annotations

import threading
from typing import Any, Dict, Optional, Tuple, Type

import genpy
import rospy
import rospy.topics

from . import _rospy_compat as compat
from ._runtime import _dds_participant, _log, _node, announce_to_ros2
from .dds.endpoints import DDSWriter, make_user_data
from .dds.types import DDSType, dds_topic_name, dds_type_for
from .exceptions import MicrosRtError
from .qos import (
    AdvertiseQoSOptions,
    SubscribeQoSOptions,
    TransportPriority,
    check_compatibility,
    priority_socket_priority,
    priority_tos,
    writer_qos,
)

__all__ = ["Publisher"]


class _Publication:
    """Per topic and process: the rospy publisher and the DDS writer."""

    def __init__(self, topic: str, data_class: Type[genpy.Message], queue_size: Optional[int],
                 latch: bool, options: AdvertiseQoSOptions) -> None:
        self.topic = topic
        self.data_class = data_class
        self.latch = latch
        self.options = options
        self.queue_size = queue_size
        self.refcount = 0
        self.lock = threading.Lock()
        self.connections: Dict[str, compat.DDSConnection] = {}
        self.dds_type: Optional[DDSType] = None
        self.writer: Optional[DDSWriter] = None
        participant = _dds_participant()
        if participant is not None:
            try:
                self.dds_type = dds_type_for(data_class)
                qos = writer_qos(options, queue_size=queue_size, latch=latch,
                                 user_data=make_user_data(graph=_node.graph, node=compat.caller_id()))
                self.writer = DDSWriter(participant, dds_topic_name(topic), self.dds_type, qos)
                announce_to_ros2(add_writer=self.writer.guid)
                prio = options.transport_priority
                participant.mark_priority(int(prio), priority_tos(prio), priority_socket_priority(prio))
            except MicrosRtError as exc:
                _log.warning("micros_rt: topic %s will use TCPROS only: %s", topic, exc)
                self.writer = None
        # the hook first: a subscriber may call requestTopic as soon as rospy registers
        compat.register_publication(topic, self)
        self.rospy_pub = rospy.Publisher(topic, data_class, queue_size=queue_size, latch=latch)
        self.impl = self.rospy_pub.impl

    # negotiation (XML-RPC thread)
    def judge_dds(self, topic: str, subscriber: str, params: Any) -> Tuple[bool, Any]:
        if self.writer is None or self.dds_type is None:
            return False, (f"topic {topic}: subscriber {subscriber} asked for DDS but DDS is unavailable in "
                           f"this publisher process; using TCPROS")
        if not isinstance(params, dict):
            return False, f"topic {topic}: malformed DDS parameters from {subscriber}: {params!r}"
        participant = _dds_participant()
        domain = params.get("domain")
        if participant is None or domain != participant.domain_id:
            return False, (f"topic {topic}: subscriber {subscriber} is on DDS domain {domain}, this publisher on "
                           f"{participant.domain_id if participant else 'none'}; set the same ROS_DOMAIN_ID on "
                           f"both to use DDS. Using TCPROS")
        md5 = params.get("md5")
        if md5 not in ("*", self.dds_type.md5sum):
            return False, (f"topic {topic}: message type mismatch with {subscriber} (md5 {md5} vs "
                           f"{self.dds_type.md5sum}); not using DDS")
        if params.get("type") != self.dds_type.type_name:
            return False, f"topic {topic}: DDS type {params.get('type')} != {self.dds_type.type_name}"
        requested = SubscribeQoSOptions.from_dict(params.get("qos") or {}, source=f"subscriber {subscriber}")
        verdict = check_compatibility(self.options, requested, topic=topic, offered_latch=self.latch)
        if not verdict.compatible:
            return False, (f"DDS QoS mismatch with subscriber {subscriber}, falling back to TCPROS: "
                           f"{verdict.reason}")
        reader = str(params.get("reader", ""))
        info = (f"DDS connection on topic {dds_topic_name(topic)} to reader {reader} "
                f"(writer {self.writer.guid}, {'best effort' if self.options.using_best_effort_protocol else 'reliable'}"
                f", priority {self.options.transport_priority.name})")
        conn = compat.DDSConnection(topic, subscriber, "o", info, peer_guid=reader,
                                    on_close=self._connection_closed)
        with self.lock:
            old = self.connections.get(subscriber)
            self.connections[subscriber] = conn
        if old is not None:
            old.close()
        compat.add_pseudo_connection(topic, conn, publisher=True)
        return True, {"writer": self.writer.guid, "latch": self.latch, "qos": self.options.to_dict(),
                      "participant": participant.guid}

    def on_tcpros_connection(self, conn: Any, sock: Any) -> None:
        """A TCPROS subscriber connected (rospy thread): mark its socket with our transport priority.

        IP_TOS carries the DSCP (:func:`priority_tos`); SO_PRIORITY (:func:`priority_socket_priority`)
        picks the local queueing band. SO_PRIORITY is set after IP_TOS, which overwrites it on Linux.
        NORMAL leaves the socket as it is.
        """
        prio = self.options.transport_priority
        if prio == TransportPriority.NORMAL or sock is None:
            return
        import socket as _socket

        tos = priority_tos(prio)
        family = sock.family
        if family == _socket.AF_INET6:
            sock.setsockopt(_socket.IPPROTO_IPV6, _socket.IPV6_TCLASS, tos)
        elif family == _socket.AF_INET:
            sock.setsockopt(_socket.IPPROTO_IP, _socket.IP_TOS, tos)
        else:
            return  # unix sockets carry no TOS
        if hasattr(_socket, "SO_PRIORITY"):
            sock.setsockopt(_socket.SOL_SOCKET, _socket.SO_PRIORITY, priority_socket_priority(prio))
        _log.debug("micros_rt: topic %s: TCPROS link to %s marked TOS 0x%02x (%s)", self.topic,
                   getattr(conn, "endpoint_id", "?"), tos, prio.name)

    def _connection_closed(self, conn: compat.DDSConnection) -> None:
        with self.lock:
            if self.connections.get(conn.endpoint_id) is conn:
                del self.connections[conn.endpoint_id]

    def housekeeping(self) -> None:
        """Drop pseudo-connections whose DDS reader went away (matched status)."""
        if self.writer is None or not self.connections:
            return
        matched = set(self.writer.matched_reader_guids())
        for conn in list(self.connections.values()):
            if conn.peer_guid in matched:
                conn.seen = True
            elif conn.seen:
                _log.debug("micros_rt: topic %s: DDS subscriber %s is gone", self.topic, conn.endpoint_id)
                compat.remove_pseudo_connection(self.topic, conn, publisher=True)
                conn.close()

    def ready_connections(self) -> int:
        """Subscribers a message published now reaches: TCPROS links, and DDS subscribers whose
        reader the writer has matched (negotiation precedes DDS discovery by a few milliseconds;
        counting those early would let a "wait for a subscriber, then publish" loop lose its first
        messages)."""
        impl = self.impl
        if impl is None:
            return 0
        conns = list(self.connections.values())
        n_tcp = max(len(impl.connections) - len(conns), 0)
        if not conns or self.writer is None:
            return n_tcp
        matched = set(self.writer.matched_reader_guids())
        return n_tcp + sum(1 for c in conns if c.peer_guid in matched)

    def publish(self, msg: Any) -> None:
        impl = self.impl
        if impl is None or impl.closed:
            raise rospy.ROSException(f"publish() to a closed topic {self.topic}")
        impl.acquire()
        try:
            writer = self.writer
            if writer is not None and (writer.matched_count or self.latch):
                try:
                    writer.write(msg)
                except (TypeError, ValueError, AttributeError, OverflowError, UnicodeError) as exc:
                    raise rospy.ROSSerializationException(
                        f"topic {self.topic}: cannot serialize {type(msg).__name__}: {exc}") from exc
                except Exception as exc:  # DDS write failure: keep TCPROS peers served
                    _log.warning("micros_rt: topic %s: DDS write failed: %s", self.topic, exc)
            if len(impl.connections) > len(self.connections):  # some are TCPROS links
                try:
                    impl.publish(msg)
                except genpy.SerializationError as exc:
                    raise rospy.ROSSerializationException(str(exc)) from exc
            elif self.latch:
                impl.latch = msg  # a later TCPROS subscriber still gets the latched message
        finally:
            impl.release()

    def close(self) -> None:
        compat.register_publication(self.topic, None)
        with _node.lock:
            if _node.publications.get(self.topic) is self:
                del _node.publications[self.topic]
        for conn in list(self.connections.values()):
            conn.close()
        if self.writer is not None:
            if not rospy.is_shutdown():
                announce_to_ros2(remove=self.writer.guid)
            self.writer.close()
            self.writer = None
        try:
            self.rospy_pub.unregister()
        except Exception:
            pass


class Publisher:
    """Returned by :meth:`NodeHandle.advertise`; rospy's Publisher API."""

    def __init__(self, pub: _Publication) -> None:
        self._pub: Optional[_Publication] = pub
        self.resolved_name = pub.topic
        self.name = pub.topic
        self.data_class = pub.data_class
        self.type = pub.data_class._type
        self.md5sum = pub.data_class._md5sum

    @property
    def qos(self) -> AdvertiseQoSOptions:
        """The QoS this publisher's topic uses (after merging the YAML profile)."""
        if self._pub is None:
            raise rospy.ROSException("publisher is unregistered")
        return self._pub.options

    def publish(self, *args: Any, **kwds: Any) -> None:
        """Publish a message (or its fields), to DDS readers and TCPROS peers alike."""
        pub = self._pub
        if pub is None:
            raise rospy.ROSException("publish() to an unregistered() handle")
        if len(args) == 1 and not kwds and type(args[0]) is pub.data_class:
            pub.publish(args[0])  # the common case, without rospy's argument parsing
        else:
            pub.publish(rospy.topics.args_kwds_to_message(pub.data_class, args, kwds))

    def get_num_connections(self) -> int:
        """Subscribers this topic reaches now, over TCPROS and DDS (DDS ones once discovery matched them)."""
        return 0 if self._pub is None else self._pub.ready_connections()

    def get_dds_connections(self) -> int:
        return 0 if self._pub is None else len(self._pub.connections)

    def unregister(self) -> None:
        """Stop publishing; the topic's writer goes when its last Publisher does."""
        pub, self._pub = self._pub, None
        if pub is None:
            return
        with _node.lock:
            pub.refcount -= 1
            last = pub.refcount <= 0
        if last:
            pub.close()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.unregister()

    close = unregister
