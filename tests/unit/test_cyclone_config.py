"""micros_rt's Cyclone configuration: the participant lease (how fast a dead peer is noticed), layering
under a user's CYCLONEDDS_URI, and that a real Cyclone participant accepts what micros_rt writes."""

from __future__ import annotations

import pytest

from micros_rt.dds.participant import (
    DEFAULT_LEASE_DURATION,
    LOOPBACK_CONFIG,
    cyclone_config,
    lease_duration,
    micros_rt_defaults,
)
from micros_rt.exceptions import DDSUnavailableError


def test_default_lease_notices_a_dead_peer_within_two_seconds() -> None:
    assert DEFAULT_LEASE_DURATION <= 2.0
    assert lease_duration({}) == DEFAULT_LEASE_DURATION
    assert f"<LeaseDuration>{DEFAULT_LEASE_DURATION:g}s</LeaseDuration>" in micros_rt_defaults({})


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
    assert first == micros_rt_defaults({})
    assert rest == "file:///etc/robot/cyclone.xml"


def test_loopback_and_interface_configs_carry_the_lease() -> None:
    assert cyclone_config({"ROS_IP": "127.0.0.1"}) == f"{micros_rt_defaults({})},{LOOPBACK_CONFIG}"
    cfg = cyclone_config({"ROS_IP": "10.1.2.3"})
    assert cfg.startswith(micros_rt_defaults({})) and 'address="10.1.2.3"' in cfg


def test_cyclone_accepts_the_layered_configuration() -> None:
    # a real participant on a private domain, from micros_rt's defaults layered over the loopback config
    from cyclonedds.domain import Domain, DomainParticipant

    domain = Domain(229, cyclone_config({"ROS_IP": "127.0.0.1", "MICROS_RT_LEASE_DURATION": "3"}))
    participant = DomainParticipant(229)
    assert str(participant.guid)
    del participant, domain
