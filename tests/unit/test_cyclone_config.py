"""micros_rt's Cyclone configuration: the participant lease (how fast a dead peer is noticed), layering
under a user's CYCLONEDDS_URI, and that a real Cyclone participant accepts what micros_rt writes."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List

import pytest

from micros_rt.transports.dds.participant import (
    DEFAULT_LEASE_DURATION,
    DEFAULT_SHM_LEASE_DURATION,
    DEFAULT_NETWORK_LEASE_DURATION,
    LOOPBACK_CONFIG,
    cyclone_config,
    lease_duration,
    micros_rt_defaults,
    send_buffer,
)
from micros_rt.exceptions import DDSUnavailableError


def test_default_lease_notices_a_dead_peer_within_two_seconds_on_loopback_when_dds_carries_the_data() -> None:
    assert DEFAULT_LEASE_DURATION <= 2.0
    for env in ({"ROS_IP": "127.0.0.1"}, {"ROS_HOSTNAME": "localhost"}, {"ROS_IP": "::1"}):
        env = dict(env, MICROS_RT_DISABLE_SHM="1")
        assert lease_duration(env) == DEFAULT_LEASE_DURATION
        assert f"<LeaseDuration>{DEFAULT_LEASE_DURATION:g}s</LeaseDuration>" in micros_rt_defaults(env)


@pytest.mark.parametrize("env", [{"ROS_IP": "127.0.0.1"}, {"ROS_IP": "127.0.0.1", "MICROS_RT_DISABLE_SHM": "0"}])
def test_with_shared_memory_on_the_loopback_lease_is_longer(env: Dict[str, str]) -> None:
    # shared memory notices a dead local node; the lease then only paces the announcements to every peer
    assert DEFAULT_LEASE_DURATION < DEFAULT_SHM_LEASE_DURATION < DEFAULT_NETWORK_LEASE_DURATION
    assert lease_duration(env) == DEFAULT_SHM_LEASE_DURATION
    assert f"<LeaseDuration>{DEFAULT_SHM_LEASE_DURATION:g}s</LeaseDuration>" in micros_rt_defaults(env)


def test_network_lease_outlasts_a_ten_second_link_outage() -> None:
    # a match that survives the outage lets the reliable stream resume with the writer's history
    assert DEFAULT_NETWORK_LEASE_DURATION > 10.0
    assert lease_duration({"ROS_IP": "10.1.2.3"}) == DEFAULT_NETWORK_LEASE_DURATION
    assert "<LeaseDuration>15s</LeaseDuration>" in cyclone_config({"ROS_IP": "10.1.2.3"})


@pytest.mark.parametrize("raw,value", [("3", 3.0), ("0.5", 0.5), (" 10 ", 10.0), ("3600", 3600.0)])
def test_lease_from_environment(raw: str, value: float) -> None:
    env = {"MICROS_RT_LEASE_DURATION": raw, "ROS_IP": "127.0.0.1"}
    assert lease_duration(env) == value
    assert f"<LeaseDuration>{value:g}s</LeaseDuration>" in cyclone_config(env)


@pytest.mark.parametrize("raw", ["abc", "0.1", "-1", "4000", "nan"])
def test_bad_lease_is_an_error_naming_the_variable(raw: str) -> None:
    with pytest.raises(DDSUnavailableError, match="MICROS_RT_LEASE_DURATION"):
        lease_duration({"MICROS_RT_LEASE_DURATION": raw})


def test_defaults_come_first_so_the_user_file_overrides_them() -> None:
    cfg = cyclone_config({"CYCLONEDDS_URI": "file:///etc/robot/cyclone.xml", "ROS_IP": "127.0.0.1"})
    first, rest = cfg.split(",", 1)
    assert first == micros_rt_defaults({"ROS_IP": "127.0.0.1"})
    assert rest == "file:///etc/robot/cyclone.xml"


def test_loopback_and_interface_configs_carry_the_lease() -> None:
    loop = {"ROS_IP": "127.0.0.1"}
    assert cyclone_config(loop) == f"{micros_rt_defaults(loop)},{LOOPBACK_CONFIG}"
    net = {"ROS_IP": "10.1.2.3"}
    cfg = cyclone_config(net)
    assert cfg.startswith(micros_rt_defaults(net)) and 'address="10.1.2.3"' in cfg


def test_cyclone_accepts_the_layered_configuration() -> None:
    # a real participant on a private domain, from micros_rt's defaults layered over the loopback config
    from cyclonedds.domain import Domain, DomainParticipant

    domain = Domain(229, cyclone_config({"ROS_IP": "127.0.0.1", "MICROS_RT_LEASE_DURATION": "3"}))
    participant = DomainParticipant(229)
    assert str(participant.guid)
    del participant, domain


def test_loopback_nodes_use_large_fragments_and_network_nodes_do_not() -> None:
    assert "<FragmentSize>63000B</FragmentSize>" in micros_rt_defaults({"ROS_IP": "127.0.0.1"})
    net = micros_rt_defaults({"ROS_IP": "10.1.2.3"})  # no local interface holds it: MTU unknown
    assert "FragmentSize" not in net  # 1,500 B MTUs: Cyclone's default, one packet per fragment
    # and Cyclone's 14,720 B datagrams: 64 KB ones starved a HIGH topic on a shaped link
    assert "MaxMessageSize" not in net


def test_bursts_fit_a_ros2_readers_buffer_where_dds_carries_data_to_ros2() -> None:
    # a loopback node with shared memory on talks DDS to ROS 2 nodes (Fast DDS, 212 kB receive buffers): a sample
    # leaves in bursts of at most 128 kB; where micros_rt nodes talk DDS to each other (shared memory off), and
    # between hosts, samples go whole
    from micros_rt.transports.dds.participant import ROS2_BURST_CONFIG

    assert "<MaxInitTransmit>0</MaxInitTransmit>" in ROS2_BURST_CONFIG
    assert "<MaxRexmit>128kB</MaxRexmit>" in ROS2_BURST_CONFIG
    assert ROS2_BURST_CONFIG in micros_rt_defaults({"ROS_IP": "127.0.0.1"})
    assert "BurstSize" not in micros_rt_defaults({"ROS_IP": "127.0.0.1", "MICROS_RT_DISABLE_SHM": "1"})
    assert "BurstSize" not in micros_rt_defaults({"ROS_IP": "10.1.2.3"})


def test_where_shared_memory_cannot_work_micros_rt_peers_talk_dds_and_samples_go_whole(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # no iceoryx2 wheel (aarch64): a host's micros_rt nodes exchange large samples over DDS, unthrottled
    from micros_rt.transports.shm import host

    monkeypatch.setattr(host, "_reason", "the iceoryx2 package is not installed")
    assert "BurstSize" not in micros_rt_defaults({"ROS_IP": "127.0.0.1"})


def test_network_fragments_are_one_packet_of_the_interfaces_mtu() -> None:
    from micros_rt.transports.dds.participant import interface_mtu, network_transport

    assert network_transport(1500) == network_transport(1280) == network_transport(None) == ""
    jumbo = network_transport(9000)  # a retransmission resends a fragment: one jumbo frame each
    assert "<MaxMessageSize>65500B</MaxMessageSize>" in jumbo  # 64 KB datagrams: 8 packets, fewer send calls
    assert "<FragmentSize>8844B</FragmentSize>" in jumbo and "<MaxRexmitMessageSize>8956B</MaxRexmitMessageSize>" in jumbo
    assert interface_mtu("127.0.0.1") == int(Path("/sys/class/net/lo/mtu").read_text())
    assert interface_mtu("10.255.254.253") is None


def test_cyclone_accepts_the_network_sizes() -> None:
    from cyclonedds.domain import Domain, DomainParticipant
    from micros_rt.transports.dds.participant import network_transport

    sizes = f'<CycloneDDS><Domain id="any">{network_transport(9000)}</Domain></CycloneDDS>'
    domain = Domain(227, f"{sizes},{LOOPBACK_CONFIG}")
    participant = DomainParticipant(227)
    assert str(participant.guid)
    del participant, domain


def test_loopback_writers_keep_a_fixed_window_and_readers_ask_at_once_others_keep_cyclones() -> None:
    # on loopback: writers start at, and stay at, 500 kB in flight (no slow start, no shrinking on
    # retransmits to dead readers); a reader asks for missing data after 5 ms, not 100
    loop = cyclone_config({"ROS_IP": "127.0.0.1"})
    for setting in ("<WhcHighInit>500kB</WhcHighInit>", "<WhcAdaptive>false</WhcAdaptive>", "<NackDelay>5ms</NackDelay>"):
        assert setting in loop
    for other in (cyclone_config({"ROS_IP": "10.1.2.3"}),
                  # a user's file sets watermarks that Cyclone checks the start against: micros_rt's stay out
                  cyclone_config({"ROS_IP": "127.0.0.1", "CYCLONEDDS_URI": "file:///x.xml"})):
        assert "Watermarks" not in other and "NackDelay" not in other


def test_a_users_low_writer_ceiling_still_starts_on_loopback(tmp_path: Path) -> None:
    # Cyclone refuses a start above the ceiling ("invalid watermark settings"): a user's WhcHigh of 100 kB
    from cyclonedds.domain import Domain, DomainParticipant

    user = tmp_path / "cyclone.xml"
    user.write_text('<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="lo" '
                    'multicast="false"/></Interfaces><AllowMulticast>false</AllowMulticast></General>'
                    "<Internal><Watermarks><WhcHigh>100kB</WhcHigh></Watermarks></Internal></Domain></CycloneDDS>")
    domain = Domain(228, cyclone_config({"ROS_IP": "127.0.0.1", "CYCLONEDDS_URI": f"file://{user}"}))
    participant = DomainParticipant(228)
    assert str(participant.guid)
    del participant, domain


def test_large_samples_get_a_receive_buffer_to_land_in() -> None:
    # a 1920x1080 Image is ~100 fragments in one burst: the kernel's default UDP buffer dropped them
    from micros_rt.transports.dds.participant import RECEIVE_BUFFER_CONFIG, micros_rt_defaults

    for env in ({"ROS_IP": "127.0.0.1"}, {"ROS_IP": "10.1.2.3"}):
        assert RECEIVE_BUFFER_CONFIG in micros_rt_defaults(env)
    assert 'max="8MB"' in RECEIVE_BUFFER_CONFIG and "min=" not in RECEIVE_BUFFER_CONFIG  # never fails to start


def test_loopback_discovery_reaches_a_sixty_node_robot_inside_the_domains_ports() -> None:
    from micros_rt.transports.dds.participant import LOOPBACK_MAX_PARTICIPANT_INDEX

    # a participant that finds no free index cannot start: 32 let the 34th node of a host fail
    assert f"<MaxAutoParticipantIndex>{LOOPBACK_MAX_PARTICIPANT_INDEX}</MaxAutoParticipantIndex>" in LOOPBACK_CONFIG
    assert LOOPBACK_MAX_PARTICIPANT_INDEX + 1 >= 60
    # Cyclone's ports: 7400 + 250 x domain + 10 (+1 user data) + 2 x index: the highest stays in its domain
    assert 10 + 2 * LOOPBACK_MAX_PARTICIPANT_INDEX + 1 < 250


@pytest.mark.parametrize("raw, size", [("", None), ("16384", 16384), ("16kB", 16384), ("1 MiB", 1 << 20)])
def test_send_buffer_from_environment(raw: str, size: object) -> None:
    assert send_buffer({"MICROS_RT_SEND_BUFFER": raw}) == size
    config = micros_rt_defaults({"MICROS_RT_SEND_BUFFER": raw, "ROS_IP": "127.0.0.1"})
    assert ("<SocketSendBufferSize" in config) == (size is not None), config


@pytest.mark.parametrize("raw", ["small", "16 bytes", "100", "-5k"])
def test_a_bad_send_buffer_says_what_is_expected(raw: str) -> None:
    with pytest.raises(DDSUnavailableError, match="MICROS_RT_SEND_BUFFER"):
        send_buffer({"MICROS_RT_SEND_BUFFER": raw})


def test_a_priority_participant_is_on_the_process_domain_on_the_network() -> None:
    # A HIGH and a LOW topic of one process leave with their own DSCP only from sockets of their own: a second
    # participant. Cyclone allows one domain per id in a process, so it has another id inside the process and
    # Cyclone's ExternalDomainId puts it on the process's domain outside: peers match its writers as any other.
    import time

    from cyclonedds.idl import make_idl_struct, types
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from micros_rt.transports.dds.participant import PRIORITY_DOMAIN_BASE, DDSParticipant, priority_config

    Probe: Any = make_idl_struct("Probe", "micros_rt_test::Probe", {"n": types.int32})
    env = {"ROS_IP": "127.0.0.1"}
    main = DDSParticipant(227, cyclone_config(env))
    scratch: List[str] = []
    lane = DDSParticipant(227, priority_config(227, scratch, env), local_id=PRIORITY_DOMAIN_BASE + 2270 + 2)
    try:
        assert lane.domain_id == 227 and lane.local_id != 227 and lane.guid != main.guid
        assert lane._sockets and not lane._sockets & main._sockets  # its own sockets, to mark on their own
        reader = DataReader(main.dp, Topic(main.dp, "probe", Probe))
        writer = DataWriter(lane.dp, Topic(lane.dp, "probe", Probe))
        got: List[Any] = []
        deadline = time.monotonic() + 30
        while not got and time.monotonic() < deadline:
            writer.write(Probe(n=7))
            time.sleep(0.05)
            got += reader.take(N=10)
        assert got and got[0].n == 7
    finally:
        lane.close()
        main.close()


def test_a_users_sections_for_the_domain_apply_to_the_priority_participant(tmp_path: Path) -> None:
    from micros_rt.transports.dds.participant import priority_config

    user = tmp_path / "cyclone.xml"
    text = ('<CycloneDDS><Domain id="5"><General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
            '</Domain><Domain id="6"><Tracing/></Domain></CycloneDDS>')
    user.write_text(text)
    scratch: List[str] = []
    config = priority_config(5, scratch, {"ROS_IP": "127.0.0.1",
                                          "CYCLONEDDS_URI": f"file://{user},<CycloneDDS><Domain id='5'/></CycloneDDS>"})
    try:
        (copy,) = scratch
        rewritten = Path(copy).read_text()
        # Cyclone picks sections by the id inside the process, which is another one for this participant
        assert '<Domain id="any"><General><Interfaces>' in rewritten and '<Domain id="6">' in rewritten
        assert user.read_text() == text  # the user's file is left as it was
        assert f"file://{copy}" in config and "<Domain id='any'/>" in config and str(user) not in config
        assert config.index(f"file://{copy}") < config.index("<ExternalDomainId>5</ExternalDomainId>")
    finally:
        for path in scratch:
            Path(path).unlink()
    # a file without a section for the domain is used as it is; an unreadable one is an error
    user.write_text('<CycloneDDS><Domain id="any"/></CycloneDDS>')
    scratch = []
    assert f"file://{user}" in priority_config(5, scratch, {"CYCLONEDDS_URI": str(user)}) and not scratch
    with pytest.raises(OSError):
        priority_config(5, scratch, {"CYCLONEDDS_URI": f"file://{tmp_path}/missing.xml"})
