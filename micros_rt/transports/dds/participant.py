"""The process's one Cyclone DDS participant, its network configuration, topics.

Cyclone's default configuration multicasts discovery on the machine's LAN
interface. micros_rt instead follows ROS 1's own idea of the node's address
(``ROS_IP``, then ``ROS_HOSTNAME``, then the host name): when that is a loopback
address, Cyclone binds ``lo`` with multicast off and finds peers by unicast on
127.0.0.1; otherwise it binds the interface holding that address. An explicit
``CYCLONEDDS_URI`` always wins.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import re
import socket
import threading
from typing import Any, Dict, List, Mapping, Optional, Tuple

from ...cyclone import import_cyclonedds
from ... import settings
from ...exceptions import DDSUnavailableError, SettingError
from ..netif import interface_mtu_of, interface_of
from ...log import nonblocking_logger
from .batching import close_flusher
from .congestion import SocketCongestion
from .typecache import forget_type_data, load_type_data, save_type_data

__all__ = [
    "LOOPBACK_CONFIG",
    "DDSParticipant",
    "PARTICIPANT_USER_DATA",
    "HELPER_ENCLAVE",
    "DEFAULT_LEASE_DURATION",
    "DEFAULT_SHM_LEASE_DURATION",
    "DEFAULT_NETWORK_LEASE_DURATION",
    "cyclone_config",
    "lease_duration",
    "micros_rt_defaults",
    "domain_id_from_env",
    "get_participant",
    "priority_participant",
    "priority_participants",
    "priority_config",
    "close_participant",
    "delete_entity",
]

_log = nonblocking_logger("rosout.micros_rt.dds")

#: Cyclone's reliable writers on a host's own loopback, where the network is never what is slow:
#:
#: - Writers start with a small window of unacknowledged data (``WhcHighInit``) and grow it toward 500 kB
#:   (``WhcHigh``) as acknowledgements come back: a slow start that throttled every burst right after
#:   discovery (a burst of 2,776 numpy_msg LaserScans of 8.6 KB one way at 51-54 k/s; 80-83 k/s starting at
#:   500 kB; 64 B bursts of 60,000: 180-229 k/s against 239-252 k/s). Here writers start at 500 kB.
#: - The window also shrinks by a fifth whenever a writer retransmits (``WhcAdaptive``), down to 1 kB, and
#:   grows back only while nothing is retransmitted. A subscriber killed mid-stream is retransmitted to until
#:   its lease ends, so subscribers that kept dying wore a lossless (``queue_size=None``) publisher's window
#:   down to a few samples: with listeners killed every 0.5-1 s, the 15th-16th new subscriber heard nothing
#:   and publish() blocked until PublishTimeoutError (3 runs of 18-20; none of 45 with the window fixed).
#:   Here the window stays at 500 kB.
#: - A reader that learns from a heartbeat that it misses data waits ``NackDelay`` (100 ms) before asking
#:   for it, which spares a network with many readers a storm of requests. Discovery data goes that way
#:   whenever it crosses the new participant's first announcement: a quarter of the subscribers started
#:   next to a talker heard it ~80 ms later than the rest (3 of 12, 4 of 14). Here the wait is 5 ms (14 of 14
#:   heard it within 20 ms of subscribing).
#:
#: Part of :data:`LOOPBACK_CONFIG` only: a user's ``CYCLONEDDS_URI`` (whose ``WhcHigh``/``WhcLow`` Cyclone
#: checks the start against) and other interfaces keep Cyclone's defaults.
LOOPBACK_INTERNAL = ("<Watermarks><WhcHighInit>500kB</WhcHighInit><WhcAdaptive>false</WhcAdaptive></Watermarks>"
                     "<NackDelay>5ms</NackDelay>")

#: Without multicast, a participant on loopback is found at the unicast ports of its participant index
#: (7400 + 250 x domain + 10 + 2 x index): each announces itself to the ports of every index up to this one,
#: and a participant that finds no free index cannot start. 32 (the value until now) let a 34th node of a
#: host fail ("Failed to find a free participant index"), which a 60-node robot hit: one node of the
#: benchmark's 60-node graph never connected in 130 s. 119 is the highest index whose ports stay inside the
#: domain's range of 250. Measured cost (per-thread CPU of an idle graph of benchmark nodes, 1 topic out at
#: 10 Hz, 3 in, 10 s): 10 nodes 1.06 -> 1.07 % of a core per node, 30 nodes 1.11 -> 1.27 %; 60 nodes now
#: connect (28.7 s; rospy 7.4 s).
LOOPBACK_MAX_PARTICIPANT_INDEX = 119

LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain id="any"><General>'
    '<Interfaces><NetworkInterface name="lo" multicast="false"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    f"<MaxAutoParticipantIndex>{LOOPBACK_MAX_PARTICIPANT_INDEX}</MaxAutoParticipantIndex>"
    '<Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
    f"<Internal>{LOOPBACK_INTERNAL}</Internal>"
    "</Domain></CycloneDDS>"
)

_INTERFACE_CONFIG = (
    '<CycloneDDS><Domain id="any"><General>'
    '<Interfaces><NetworkInterface address="{address}"/></Interfaces>'
    "</General></Domain></CycloneDDS>"
)


def _ros_address(env: Mapping[str, str]) -> str:
    """The address a ROS 1 node would advertise, resolved to an IP."""
    host = env.get("ROS_IP") or env.get("ROS_HOSTNAME") or socket.gethostname()
    try:
        return socket.gethostbyname(host)
    except OSError:
        return host


#: Seconds after which a peer that stopped without saying goodbye (killed, crashed) is considered
#: gone and its DDS connections dropped, when the node's address (ROS_IP/ROS_HOSTNAME) is loopback and
#: DDS carries the data between this host's micros_rt nodes (shared memory turned off): every peer is on
#: this host, where silence means death. Cyclone's default is 10 s; TCPROS notices a dead peer at once.
#: (The lease is what this node announces: it is how fast the others notice it.)
DEFAULT_LEASE_DURATION = 1.5
#: The same on loopback when shared memory carries the data between this host's micros_rt nodes (the
#: default): they notice each other's death through it (a process check, within 2 s), and DDS carries
#: ROS 2 peers (whose own lease, Fast DDS's, is 20 s) and the graph's visibility to them. A participant
#: announces itself to every other at 80 % of its lease, which at 1.5 s was most of a many-node robot's
#: DDS cost: Cyclone's threads 17 % of a core at 30 nodes; 5 s: about a third of the announcements.
DEFAULT_SHM_LEASE_DURATION = 5.0
#: The same on a real network, where silence may be a cable or a radio link that comes back: a link
#: down for less than this keeps its DDS match, and a reliable stream then resumes without losing
#: what the writer's history holds (a new match would not get it: micros_rt writers are volatile).
DEFAULT_NETWORK_LEASE_DURATION = 15.0


def _is_loopback(env: Mapping[str, str]) -> bool:
    address = _ros_address(env)
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return True  # not an IP: a name we could not resolve; micros_rt stays on loopback then


def lease_duration(env: Mapping[str, str] = os.environ) -> float:
    """The participant lease (seconds): ``MICROS_RT_LEASE_DURATION``, else, for a loopback node,
    :data:`DEFAULT_SHM_LEASE_DURATION` (:data:`DEFAULT_LEASE_DURATION` when ``MICROS_RT_DISABLE_SHM`` turns
    shared memory off), and :data:`DEFAULT_NETWORK_LEASE_DURATION` for one on a network interface."""
    try:
        value = settings.LEASE_DURATION.get(env)
        shm_off = settings.DISABLE_SHM.get(env)
    except SettingError as exc:
        raise DDSUnavailableError(str(exc)) from None
    if value is not None:
        return value
    if not _is_loopback(env):
        return DEFAULT_NETWORK_LEASE_DURATION
    return DEFAULT_LEASE_DURATION if shm_off else DEFAULT_SHM_LEASE_DURATION


#: On loopback (64 KiB MTU) samples travel in 63 KB fragments instead of Cyclone's 1,344 B, which suits
#: a 1,500 B Ethernet MTU: a 1920x1080 rgb8 Image (6.2 MB) round trip went from ~180 ms to ~20 ms.
LOOPBACK_TRANSPORT = "<General><MaxMessageSize>65500B</MaxMessageSize><FragmentSize>63000B</FragmentSize></General>"


#: A large sample arrives as a burst of fragments (a 1920x1080 Image: ~100 datagrams of 63 KB); with the
#: kernel's default UDP receive buffer a burst of them overflowed it, and the lost fragments went through
#: Cyclone's NACK/retransmit cycle: 64 Images/s one way. Up to 8 MB (what the kernel allows, see
#: net.core.rmem_max; nothing fails when it allows less): 363-400 Images/s (stock rospy: 137-152).
RECEIVE_BUFFER_CONFIG = '<SocketReceiveBufferSize max="8MB"/>'


#: On a loopback node with shared memory on, DDS carries what a micros_rt node exchanges with the ROS 2 nodes of its
#: host (micros_rt nodes of the host use shared memory), and Fast DDS, rclpy's DDS, reads with the kernel's default
#: UDP receive buffer (``net.core.rmem_default``, 212,992 B here: three 63 KB datagrams). Cyclone sends a new sample
#: whole, and presumes a reader that is not Cyclone's has a buffer as large as its own socket's (8 MB): a 640x480
#: rgb8 Image (921 kB, 15 datagrams) overflowed Fast DDS's socket on every frame, the repair bursts overflowed it
#: again, and a reader of depth 10 got 48-209 of 240 frames at p50 61-218 ms (benchmarks/camera_ros2.py). With a
#: sample's first burst and each repair burst at most 128 kB (two datagrams; the rest follows on the reader's
#: NACKs, ~3 ms a round here): 240 of 240, no datagram dropped, p50 25 ms (rclpy to rclpy 14-15 ms). Cyclone's
#: limit is per writer, for every reader of it; where micros_rt nodes of one host talk DDS to each other (shared
#: memory turned off by ``MICROS_RT_DISABLE_SHM``, or unusable: no iceoryx2 wheel, as on aarch64) large samples go
#: whole, as before (the limit would cost them a NACK round per 128 kB). While a best-effort reader is matched, a
#: writer sends every sample whole to all its readers (Cyclone's rule: it cannot repair for that one).
ROS2_BURST_CONFIG = "<BurstSize><MaxInitTransmit>0</MaxInitTransmit><MaxRexmit>128kB</MaxRexmit></BurstSize>"


#: Between hosts a large sample leaves in datagrams of up to 64 KB (Cyclone's default: 14,720 B), which the
#: kernel cuts into IP fragments of the link's MTU. What a sample costs there is per packet and per send
#: call, in the sending host's kernel (with hosts in network namespaces behind a Linux bridge, the receivers'
#: too): a 640x480 rgb8 Image in 14,720 B datagrams took ~63 send calls, in 64 KB ones 15, and the same ~630
#: packets at MTU 1500 either way. Datagrams of one packet each (no IP fragments) were 2-3x slower still.
#: Cyclone's fragments (the unit a lost packet costs: a retransmission resends whole fragments) stay one
#: packet of the interface's MTU, ``MTU - 156`` (Cyclone's 1,344 B at MTU 1500), and retransmissions go in
#: datagrams of one packet (``MTU - 44``, Cyclone's 1,456 B at 1500), so a lossy link repairs a large sample
#: packet by packet as before. Measured between namespace hosts (benchmarks/cross_host.py, Image 640x480 at
#: 30 Hz): MTU 1500, 1 subscriber host p50 6.1-7.1 -> 4.9-5.3 ms, 4 subscriber hosts 16 -> 11 ms.
#:
#: Only on jumbo-frame interfaces (MTU above 1,500), where a 64 KB datagram is a few packets: at 1,500 it is
#: 44 IP fragments and the loss of any one loses all of them, and on a link that is the bottleneck (a radio
#: link, a 40 Mbit/s tbf queue in tests/integration/test_constrained_link.py) the camera's 64 KB datagrams
#: starved a HIGH 1 kHz control topic of the same process: 852-948 of ~5,850 delivered against 5,901-5,953
#: with Cyclone's 14,720 B datagrams. The radio link is the setting micros_rt's QoS is for, so at MTU 1,500
#: and below Cyclone's sizes stay (they are one packet per fragment already).
NETWORK_MAX_MESSAGE = 65500


def send_buffer(env: Mapping[str, str] = os.environ) -> Optional[int]:
    """The UDP send buffer Cyclone asks for (bytes): ``MICROS_RT_SEND_BUFFER``, else None (Cyclone's own).

    A process whose DDS traffic crosses a slow link and is all below HIGH (a relay's LOW process, a camera
    node) keeps that link's queue short with a small buffer: a datagram waiting in the link's queue still
    counts against its socket's buffer, so the process never has more than about twice this in the queue
    (40 Mbit/s tbf, the relay's LOW process at 16 kB: control p50/p99 through the other process 4.6/9.9 ms
    instead of 23/31 ms, the camera's frames unchanged; at 4 kB the camera starved). Never for a process
    with HIGH topics: they wait in the same socket.
    """
    try:
        return settings.SEND_BUFFER.get(env)
    except SettingError as exc:
        raise DDSUnavailableError(str(exc)) from None


def interface_mtu(address: str) -> Optional[int]:
    """The MTU of the local interface holding IPv4 ``address``; None when no interface holds it."""
    name = interface_of(address)
    return None if name is None else interface_mtu_of(name)


def network_transport(mtu: Optional[int]) -> str:
    """Cyclone's datagram and fragment sizes for a network interface of ``mtu`` bytes (see
    :data:`NETWORK_MAX_MESSAGE`): on jumbo frames 64 KB datagrams, fragments and retransmissions of one
    packet each; at MTU 1,500 and below Cyclone's own sizes."""
    if mtu is None or mtu <= 1500:
        return ""  # Cyclone's own sizes: see NETWORK_MAX_MESSAGE for why not 64 KB datagrams here
    mtu = min(mtu, 65535)
    return (f"<General><MaxMessageSize>{NETWORK_MAX_MESSAGE}B</MaxMessageSize>"
            f"<FragmentSize>{mtu - 156}B</FragmentSize>"
            f"<MaxRexmitMessageSize>{mtu - 44}B</MaxRexmitMessageSize></General>")


def micros_rt_defaults(env: Mapping[str, str] = os.environ) -> str:
    """Settings micros_rt applies under any configuration (a user's ``CYCLONEDDS_URI`` overrides them):
    the participant lease, a receive buffer large samples fit in, the send buffer when
    ``MICROS_RT_SEND_BUFFER`` asks (:func:`send_buffer`), and large datagrams (on a loopback node, large
    fragments too, and with shared memory on, bursts ROS 2 readers' buffers hold: :data:`ROS2_BURST_CONFIG`;
    on a network, fragments of the interface's MTU)."""
    burst = ""
    if _is_loopback(env):
        transport = LOOPBACK_TRANSPORT
        if not _shm_off(env):
            burst = ROS2_BURST_CONFIG
    else:
        transport = network_transport(interface_mtu(_ros_address(env)))
    size = send_buffer(env)
    sending = "" if size is None else f'<SocketSendBufferSize min="{size}B" max="{size}B"/>'
    return (f'<CycloneDDS><Domain id="any">{transport}<Discovery>'
            f"<LeaseDuration>{lease_duration(env):g}s</LeaseDuration>"
            f"</Discovery><Internal>{RECEIVE_BUFFER_CONFIG}{sending}{burst}</Internal></Domain></CycloneDDS>")


def _shm_off(env: Mapping[str, str]) -> bool:
    """Whether this process's micros_rt peers of the host talk DDS, not shared memory: turned off
    (``MICROS_RT_DISABLE_SHM``), or shared memory cannot work here (no iceoryx2 wheel, as on aarch64; /dev/shm
    missing or full)."""
    from ..shm.host import unavailable_reason  # the one question DDS's configuration asks of shared memory

    try:
        return unavailable_reason(env) is not None
    except SettingError as exc:
        raise DDSUnavailableError(str(exc)) from None


def cyclone_config(env: Mapping[str, str] = os.environ) -> str:
    """The Cyclone configuration micros_rt uses: its defaults, then the network configuration.

    With ``CYCLONEDDS_URI`` set, that is the network configuration (Cyclone reads comma-separated
    sources in order, later ones override earlier ones: the user's file wins wherever it speaks).
    Otherwise micros_rt follows ROS 1's address: loopback -> :data:`LOOPBACK_CONFIG`, else the
    interface that holds the address.

    >>> LOOPBACK_CONFIG in cyclone_config({"ROS_IP": "127.0.0.1"})
    True
    """
    return f"{micros_rt_defaults(env)},{_network_config(env)}"


def _network_config(env: Mapping[str, str]) -> str:
    user = env.get("CYCLONEDDS_URI", "").strip()
    if user:
        return user
    if _is_loopback(env):
        return LOOPBACK_CONFIG
    return _INTERFACE_CONFIG.format(address=_ros_address(env))


def domain_id_from_env(env: Mapping[str, str] = os.environ) -> int:
    """``ROS_DOMAIN_ID`` as in ROS 2 (default 0); a bad value is an error that says so."""
    raw = env.get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    try:
        value = int(raw)
    except ValueError:
        raise DDSUnavailableError(f"ROS_DOMAIN_ID={raw!r} is not an integer (expected 0..232)") from None
    if not 0 <= value <= 232:
        raise DDSUnavailableError(f"ROS_DOMAIN_ID={value} is out of range (expected 0..232)")
    return value


#: User data of every micros_rt participant: rmw's ``enclave=/;`` (what ROS 2 nodes announce, so ROS 2 tools read
#: it as theirs) and micros_rt's mark, by which the host's ROS 2 watcher (:mod:`.watch`) tells micros_rt from ROS 2
PARTICIPANT_USER_DATA = b"enclave=/;micros_rt=1;"
#: The ROS 2 enclave of micros_rt's own rclpy processes (the services helper, :mod:`micros_rt.services.gateway`):
#: rmw puts ``enclave=/micros_rt;`` in their participants' user data, by which the watcher tells them from ROS 2
#: nodes. Without security (``ROS_SECURITY_ENABLE``) an enclave names nothing else.
HELPER_ENCLAVE = "/micros_rt"


class DDSParticipant:
    """One Cyclone domain participant and the topics created on it.

    Created through :func:`get_participant` (the process's participant: its readers, and its writers of one
    transport priority) or :func:`priority_participant` (writers of another priority, with sockets of their
    own); ``close()`` releases every entity.
    """

    def __init__(self, domain_id: int, config: str, *, local_id: Optional[int] = None) -> None:
        import_cyclonedds()
        from cyclonedds.core import DDSException
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.qos import Policy, Qos

        self.domain_id = domain_id
        #: the id Cyclone knows this participant's domain by in this process (another one than
        #: ``domain_id`` for a priority participant, which is on ``domain_id`` on the network)
        self.local_id = domain_id if local_id is None else local_id
        from .marking import process_udp_sockets

        before = set(process_udp_sockets())
        try:
            # A Domain with an explicit config keeps our settings out of the
            # process environment (CYCLONEDDS_URI stays the user's).
            self._domain = Domain(self.local_id, config)
            # marked as micros_rt's: the host's ROS 2 watcher (watch.py) tells ROS 2 participants from these
            self.dp = DomainParticipant(self.local_id, qos=Qos(Policy.Userdata(PARTICIPANT_USER_DATA)))
        except DDSException as exc:
            raise DDSUnavailableError(
                f"cannot start a Cyclone DDS participant on domain {domain_id}: {exc}; {_config_advice()}") from exc
        self.guid = str(self.dp.guid)
        # the sockets Cyclone just opened: what transport priority marks (see marking.py)
        self._sockets = set(process_udp_sockets()) - before
        self._topics: Dict[str, Tuple[Any, int]] = {}  # name -> (Topic, references)
        self._lock = threading.Lock()
        self._priority: Optional[int] = None
        #: whether a large write of this participant waits for room in its transmit socket
        self.congestion = SocketCongestion()
        #: the send buffer :meth:`limit_send_buffer` gave its sockets (None: Cyclone's, or MICROS_RT_SEND_BUFFER)
        self.send_buffer: Optional[int] = None
        self.closed = False

    @property
    def priority(self) -> Optional[int]:
        """The transport priority level this participant's sockets are marked for (None: no writer yet)."""
        return self._priority

    def claim_priority(self, level: int, tos: int, so_priority: int) -> bool:
        """Let a writer of transport priority ``level`` use this participant's sockets: True when they carry
        that level (the first writer's level marks them), False when they carry another one (that writer
        belongs on :func:`priority_participant`'s participant for its level)."""
        with self._lock:
            if self._priority is not None:
                return self._priority == level
            self._priority = level
        if tos:  # unmarked is the default
            self._mark(tos, so_priority)
        return True

    def mark_priority(self, level: int, tos: int, so_priority: int) -> None:
        """Mark this participant's traffic for a writer of transport priority ``level`` when it is higher than
        what marks it now: what a process without priority participants does (see
        :mod:`micros_rt.transports.dds.marking`)."""
        with self._lock:
            if self._priority is not None and level <= self._priority:
                return
            first = self._priority is None
            self._priority = level
        if first and tos == 0:
            return  # unmarked is the default
        self._mark(tos, so_priority)

    def limit_send_buffer(self, size: int) -> None:
        """Give this participant's sockets a UDP send buffer of ``size`` bytes (the kernel doubles it), once: its
        writers (all below HIGH) then keep at most about twice that queued in a slow link, where HIGH topics'
        datagrams (another participant's sockets) would wait behind them (:func:`~micros_rt.qos.links.send_buffer_for`)."""
        from .marking import limit_send_buffers

        with self._lock:
            if self.send_buffer is not None:
                return
            self.send_buffer = size
        n = limit_send_buffers(self._sockets, size)
        _log.info("micros_rt: DDS writers of transport priority %s use a %d-byte UDP send buffer (%d sockets): "
                  "the profile names a link of limited bandwidth, and they keep little queued in it",
                  self._priority, size, n)

    def _mark(self, tos: int, so_priority: int) -> None:
        from .marking import mark_udp_sockets

        n = mark_udp_sockets(self._sockets, tos, so_priority)
        _log.debug("micros_rt: DDS participant %s marked TOS 0x%02x on %d sockets", self.guid, tos, n)

    def topic(self, name: str, idl_class: Any) -> Any:
        """The Topic ``name`` with type ``idl_class``, shared by the process's readers and writers of it:
        each call takes a reference that :meth:`release_topic` gives back (the last one deletes it)."""
        with self._lock:
            found = self._topics.get(name)
            if found is not None:
                topic, refs = found
                if topic.data_type is not idl_class:
                    raise DDSUnavailableError(
                        f"DDS topic {name!r} is already used in this process with type "
                        f"{topic.data_type.__idl_typename__}, not {idl_class.__idl_typename__}")
                self._topics[name] = (topic, refs + 1)
                return topic
            topic = self._new_topic(name, idl_class)
            self._topics[name] = (topic, 1)
            return topic

    def _new_topic(self, name: str, idl_class: Any) -> Any:
        import_cyclonedds()
        from cyclonedds.core import DDSException
        from cyclonedds.topic import Topic

        if load_type_data(idl_class):
            try:
                topic = Topic(self.dp, name, idl_class)
            except DDSException as exc:  # bytes Cyclone refuses: build them as if never cached
                _log.warning("micros_rt: cached DDS type data for %s refused (%s); rebuilding it",
                             idl_class.__idl_typename__, exc)
                forget_type_data(idl_class)
                topic = Topic(self.dp, name, idl_class)
        else:
            topic = Topic(self.dp, name, idl_class)
        save_type_data(idl_class)  # a no-op when its file exists
        return topic

    def release_topic(self, name: str) -> None:
        """Give back a reference taken by :meth:`topic`; the Topic entity goes with the last one."""
        with self._lock:
            found = self._topics.get(name)
            if found is None:
                return
            topic, refs = found
            if refs > 1:
                self._topics[name] = (topic, refs - 1)
                return
            del self._topics[name]
        delete_entity(topic)

    def close(self) -> None:
        """Delete the participant and everything created on it; harmless twice."""
        if self.closed:
            return
        self.closed = True
        delete_entity(self.dp)  # entities created on it go with it


def delete_entity(entity: Any) -> None:
    """Delete a cyclonedds entity now (not at garbage collection); harmless twice."""
    try:
        ref = entity._ref
        if ref in entity._entities:
            del entity._entities[ref]
            entity._delete(ref)
    except Exception as exc:  # closing must go on
        _log.debug("deleting DDS entity: %s", exc)


def _config_advice(env: Mapping[str, str] = os.environ) -> str:
    """What to check when Cyclone refuses to start a participant: the configuration it was given."""
    user = env.get("CYCLONEDDS_URI", "").strip()
    if user:
        return f"check the Cyclone configuration CYCLONEDDS_URI names ({user[:200]})"
    return (f"check that this host has the interface of ROS_IP/ROS_HOSTNAME's address ({_ros_address(env)}), "
            "or point CYCLONEDDS_URI at a Cyclone configuration")


_lock = threading.Lock()
_participant: Optional[DDSParticipant] = None
_failed: Optional[str] = None


def get_participant() -> Optional[DDSParticipant]:
    """The process participant, created on first use; None when DDS cannot start.

    The failure is logged once, in words, and micros_rt then uses TCPROS for
    every connection of this process.
    """
    global _participant, _failed
    with _lock:
        if _participant is not None and not _participant.closed:
            return _participant
        if _failed is not None:
            return None
        if settings.DISABLE_DDS.get():
            _failed = "MICROS_RT_DISABLE_DDS is set"
            _log.warning("micros_rt: DDS disabled (MICROS_RT_DISABLE_DDS is set); using TCPROS for every topic")
            return None
        try:
            import_cyclonedds()  # once per process, whole, by one thread (micros_rt/cyclone.py)
            _participant = DDSParticipant(domain_id_from_env(), cyclone_config())
        except Exception as exc:
            _failed = str(exc)
            _log.warning("micros_rt: DDS is unavailable in this process (%s); every topic falls back to TCPROS "
                         "or shared memory", exc)
            return None
        return _participant


#: A priority participant's domain id inside this process: ``PRIORITY_DOMAIN_BASE + 10 x domain + level``,
#: ids no ROS 2 domain uses (0..232); on the network it is on the process's domain (``ExternalDomainId``).
PRIORITY_DOMAIN_BASE = 10000

_by_priority: Dict[Tuple[int, int], DDSParticipant] = {}  # (domain, transport priority level) -> its participant
_priority_failed: Optional[str] = None


def _own_sections(domain_id: int) -> "re.Pattern[str]":
    return re.compile(r'(<Domain\b[^>]*\bid\s*=\s*)(["\'])\s*' + str(domain_id) + r'\s*\2', re.IGNORECASE)


def priority_config(domain_id: int, scratch: List[str], env: Mapping[str, str] = os.environ) -> str:
    """The configuration of a priority participant: the process participant's (:func:`cyclone_config`), with
    ``ExternalDomainId`` putting it on ``domain_id`` on the network.

    Cyclone picks a configuration's ``<Domain id="N">`` sections by the domain's id inside the process, which
    differs here: in a user's ``CYCLONEDDS_URI`` the sections for ``domain_id`` apply as ``id="any"``. Inline
    XML is rewritten in place, a file that has such sections is copied, rewritten, to a temporary file whose
    path is appended to ``scratch`` (the caller removes it once the domain has started). Raises OSError when
    a file cannot be read."""
    user = env.get("CYCLONEDDS_URI", "").strip()
    if not user:
        network = _network_config(env)
    else:
        import tempfile

        own, parts = _own_sections(domain_id), []
        # sources are comma-separated: inline XML, file:// URIs or paths
        for part in re.split(r",(?=\s*(?:<|file://|/|\.|~))", user):
            part = part.strip()
            if part.startswith("<"):
                parts.append(own.sub(r"\1\2any\2", part))
            elif part:
                path = os.path.expanduser(os.path.expandvars(part[7:] if part.startswith("file://") else part))
                with open(path, encoding="utf-8") as f:
                    text = f.read()
                if own.search(text):
                    fd, path = tempfile.mkstemp(prefix="micros_rt_cyclonedds_", suffix=".xml")
                    with os.fdopen(fd, "w", encoding="utf-8") as f:
                        f.write(own.sub(r"\1\2any\2", text))
                    scratch.append(path)
                parts.append(f"file://{path}")
        network = ",".join(parts)
    external = (f'<CycloneDDS><Domain id="any"><Discovery><ExternalDomainId>{domain_id}</ExternalDomainId>'
                "</Discovery></Domain></CycloneDDS>")
    return f"{micros_rt_defaults(env)},{network},{external}"


def priority_participant(domain_id: int, level: int, tos: int, so_priority: int) -> Optional[DDSParticipant]:
    """The participant for this process's DDS writers on ``domain_id`` of transport priority ``level`` when the
    process participant's sockets carry another level (:meth:`DDSParticipant.claim_priority`); created on first use.

    Cyclone sends all data of a participant through one socket per interface, so a HIGH and a LOW topic of one
    participant would leave with one DSCP. This participant has sockets of its own, marked for ``level``. It
    is in the process's DDS domain on the network (Cyclone's ``ExternalDomainId``; in the process its domain
    has another id, since an id is one domain per process), so every DDS peer finds and matches its writers
    as any other. It costs what a participant costs: measured, ~7-9 ms to start, 5 threads, +0.2-0.3 % of a
    core idle, its discovery traffic (README, Performance, Constrained link).

    None when it cannot start: the failure is logged once, in words, and writers of every level then share
    the process participant, marked with the highest level (what a process did before).
    """
    global _priority_failed
    with _lock:
        extra = _by_priority.get((domain_id, level))
        if extra is not None and not extra.closed:
            return extra
        if _priority_failed is not None:
            return None
        scratch: List[str] = []  # rewritten copies of the user's configuration files
        try:
            extra = DDSParticipant(domain_id, priority_config(domain_id, scratch),
                                  local_id=PRIORITY_DOMAIN_BASE + 10 * domain_id + level)
        except Exception as exc:
            _priority_failed = str(exc)
            _log.warning(
                "micros_rt: cannot start a DDS participant for transport priority %d (%s); DDS topics of "
                "different priorities in this process share one socket, marked with the highest priority", level, exc)
            return None
        finally:
            for path in scratch:
                os.unlink(path)
        extra.claim_priority(level, tos, so_priority)
        _by_priority[domain_id, level] = extra
        _log.debug("micros_rt: DDS writers of transport priority %d use participant %s", level, extra.guid)
        return extra


def priority_participants() -> List[DDSParticipant]:
    """The priority participants this process started, lowest level first."""
    with _lock:
        return [_by_priority[key] for key in sorted(_by_priority) if not _by_priority[key].closed]


def close_participant() -> None:
    """Close the process participant and its priority participants (at shutdown)."""
    global _participant, _priority_failed
    with _lock:
        close_flusher()  # what batching writers still hold goes out before their participant does
        for extra in _by_priority.values():
            extra.close()
        _by_priority.clear()
        _priority_failed = None
        if _participant is not None:
            _participant.close()
            _participant = None
