"""Unit tests of ``micros-rt doctor``'s checks that need no graph (each failure names its fix) and of
``micros-rt profile check`` (library errors with file:line; which rule wins for a live topic)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from micros_rt.cli import CommandError
from micros_rt.cli import doctor
from micros_rt.cli import profile as profile_cmd
from micros_rt.cli.doctor import (
    FAIL,
    OK,
    check_address,
    check_cyclone,
    check_dds_network,
    check_domain,
    check_profile,
    judge_clocks,
)
from micros_rt.qos import QoSProfile

IFACES = {"127.0.0.1": "lo", "10.1.2.3": "eth0"}
LOOPBACK_XML = ('<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="lo" multicast="false"/>'
                "</Interfaces><AllowMulticast>false</AllowMulticast></General></Domain></CycloneDDS>")


@pytest.mark.parametrize("value", ["999", "-1", "two"])
def test_a_bad_domain_id_fails_with_a_fix(value: str) -> None:
    check = check_domain({"ROS_DOMAIN_ID": value})
    assert check.status == FAIL and value in check.detail
    assert check.fix.startswith("export ROS_DOMAIN_ID=")


def test_a_good_domain_id_passes() -> None:
    assert check_domain({"ROS_DOMAIN_ID": "232"}).status == OK
    assert "default" in check_domain({}).detail


@pytest.mark.parametrize("env,expected", [
    ({"ROS_IP": "not-an-ip"}, "is not an IP address"),
    ({"ROS_IP": "10.9.9.9"}, "not an address of this host"),
    ({"ROS_HOSTNAME": "no-such-host.invalid"}, "does not resolve"),
    ({"ROS_IP": "127.0.0.1", "ROS_HOSTNAME": "10.1.2.3"}, "rospy advertises ROS_HOSTNAME"),
    ({"ROS_IP": "127.0.0.1", "ROS_MASTER_URI": "http://10.1.2.4:11311/"}, "on another host"),
])
def test_address_problems_fail_with_a_fix(env: dict[str, str], expected: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # a name that does not resolve is answered here: looking it up for real sent a DNS query out of eth0
    real = doctor._resolve
    monkeypatch.setattr(doctor, "_resolve", lambda host: None if host.endswith(".invalid") else real(host))
    check = check_address(env, IFACES)
    assert check.status == FAIL and expected in check.detail, check
    assert check.fix


@pytest.mark.parametrize("env", [{"ROS_IP": "127.0.0.1"}, {"ROS_IP": "10.1.2.3"},
                                 {"ROS_HOSTNAME": "localhost"},
                                 {"ROS_IP": "127.0.0.1", "ROS_MASTER_URI": "http://localhost:11311/"}])
def test_consistent_addresses_pass(env: dict[str, str]) -> None:
    assert check_address(env, IFACES).status == OK


def test_dds_network_reports_what_micros_rt_picks(tmp_path: Path) -> None:
    loop = check_dds_network({"ROS_IP": "127.0.0.1"}, IFACES)
    assert loop.status == OK and "interface lo" in loop.detail and "multicast off" in loop.detail
    assert "63 KB fragments in bursts of 128 kB" in loop.detail  # what ROS 2 readers' buffers hold
    no_shm = check_dds_network({"ROS_IP": "127.0.0.1", "MICROS_RT_DISABLE_SHM": "1"}, IFACES)
    assert "63 KB fragments, " in no_shm.detail and "bursts" not in no_shm.detail
    lan = check_dds_network({"ROS_IP": "10.1.2.3"}, IFACES)
    assert lan.status == OK and "interface eth0" in lan.detail and "multicast on" in lan.detail
    cfg = tmp_path / "cyclone.xml"
    cfg.write_text(LOOPBACK_XML)
    user = check_dds_network({"ROS_IP": "10.1.2.3", "CYCLONEDDS_URI": cfg.as_uri()}, IFACES)
    assert user.status == OK and "interface lo, multicast off" in user.detail
    missing = check_dds_network({"CYCLONEDDS_URI": str(tmp_path / "missing.xml")}, IFACES)
    assert missing.status == FAIL and "cannot be read" in missing.detail and missing.fix
    lease = check_dds_network({"ROS_IP": "127.0.0.1", "MICROS_RT_LEASE_DURATION": "0"}, IFACES)
    assert lease.status == FAIL and "MICROS_RT_LEASE_DURATION" in lease.fix
    small = check_dds_network({"ROS_IP": "127.0.0.1", "MICROS_RT_SEND_BUFFER": "tiny"}, IFACES)
    assert small.status == FAIL and "MICROS_RT_SEND_BUFFER" in small.detail and "16kB" in small.fix, small
    sized = check_dds_network({"ROS_IP": "127.0.0.1", "MICROS_RT_SEND_BUFFER": "16kB"}, IFACES)
    assert sized.status == OK and "UDP send buffer 16384 B" in sized.detail, sized


def test_cyclone_starts_with_micros_rt_loopback_configuration() -> None:
    # domain 231: away from the per-run test domains (1..200); loopback only
    check = check_cyclone({"ROS_IP": "127.0.0.1", "ROS_DOMAIN_ID": "231"})
    assert check.status == OK, check


def test_profile_check_of_the_environment(tmp_path: Path) -> None:
    assert check_profile({}).status == OK
    bad = tmp_path / "bad.yaml"
    bad.write_text("publishers:\n  /a: {transport_priority: LOUD}\n")
    check = check_profile({"MICROS_RT_QOS_PROFILE": str(bad)})
    assert check.status == FAIL and f"{bad}:2:" in check.detail
    assert "micros-rt profile check" in check.fix


def test_clock_offsets_fail_only_when_surely_over_the_skew_micros_rt_warns_about() -> None:
    assert judge_clocks({}).status == OK
    near = judge_clocks({"/a": (0.002, 0.001), "/b": (-0.4, 0.001)})
    assert near.status == OK and "-400.0 ms" in near.detail and "/b" in near.detail
    assert judge_clocks({"/slow_answer": (1.3, 0.5)}).status == OK  # could be the call's own delay
    far = judge_clocks({"/a": (0.0, 0.001), "/lagging": (-2.5, 0.01)})
    assert far.status == FAIL and "/lagging" in far.detail and "chrony" in far.fix


PROFILE = textwrap.dedent("""\
    publishers:
      /chatter: {transport_priority: HIGH}
      "/cha*": {using_best_effort_protocol: true}
      "/camera/*": {msg_valid_period: 0.1}
      "^/sc[a-z]+$": {latency_budget: 0.01}
    subscribers:
      "/*": {time_filter_duration: 0.5}
    """)


def test_rule_matches_uses_the_library_precedence() -> None:
    profile = QoSProfile.from_string(PROFILE, source="qos.yaml")
    live = {"/chatter": ["/b", "/a"], "/chatter2": ["/c"], "/scan": ["/d"]}
    assert profile_cmd.rule_matches(profile, "publishers", "/chatter", live) == {"/chatter": (["/a", "/b"], None)}
    assert profile_cmd.rule_matches(profile, "publishers", "/cha*", live) == {
        "/chatter": (["/a", "/b"], "/chatter"), "/chatter2": (["/c"], None)}
    assert profile_cmd.rule_matches(profile, "publishers", "/camera/*", live) == {}
    assert set(profile_cmd.rule_matches(profile, "subscribers", "/*", live)) == {"/chatter", "/chatter2", "/scan"}
    # a ^...$ rule, which the profile applies, lists the live topics it applies to (fnmatch listed none)
    scan = profile.advertise_options("/scan")
    assert scan is not None and scan.latency_budget == 0.01
    assert profile_cmd.rule_matches(profile, "publishers", "^/sc[a-z]+$", live) == {"/scan": (["/d"], None)}


def test_profile_check_offline(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "good.yaml"
    good.write_text(PROFILE)
    assert profile_cmd.main(["check", "--offline", str(good)]) == 0
    text = capsys.readouterr().out
    assert "valid (4 publisher rules, 1 subscriber rule)" in text
    assert "/chatter: reliable, priority HIGH" in text
    bad = tmp_path / "bad.yaml"
    bad.write_text("subscribers:\n  /a:\n    deadline: 0\n")
    with pytest.raises(CommandError) as info:
        profile_cmd.main(["check", "--offline", str(bad)])
    assert f"{bad}:3:" in str(info.value) and "deadline" in str(info.value)
    linked = tmp_path / "linked.yaml"
    linked.write_text("links:\n  radio: {interface: wlan0, bandwidth: 20Mbit, reserve: 0.25}\n")
    assert profile_cmd.main(["check", "--offline", str(linked)]) == 0
    text = capsys.readouterr().out
    assert "valid (0 publisher rules, 0 subscriber rules, 1 link)" in text
    assert "link radio (interface wlan0, 20 Mbit/s, 25% kept for HIGH): topics below HIGH share 15 Mbit/s" in text
    assert "DDS writers below HIGH: a send buffer of 16,384 bytes" in text  # 20 Mbit/s: the 16 kB floor


def test_shared_memory_check_sends_a_message_through_a_channel(monkeypatch: pytest.MonkeyPatch) -> None:
    from micros_rt.cli.doctor import check_shared_memory

    monkeypatch.setenv("MICROS_RT_DISABLE_SHM", "0")  # the suite keeps it off for its other nodes
    check = check_shared_memory({"MICROS_RT_DISABLE_SHM": "0"})
    assert check.status == "OK", check
    assert "iceoryx2" in check.detail and "crossed a channel" in check.detail and "MiB free" in check.detail
    off = check_shared_memory({"MICROS_RT_DISABLE_SHM": "1"})
    assert off.status == "SKIP" and "MICROS_RT_DISABLE_SHM" in off.detail


def test_ros2_visibility_check_says_which_and_refuses_nonsense() -> None:
    from micros_rt.cli.doctor import check_ros2_visibility

    auto = check_ros2_visibility({"ROS_DOMAIN_ID": "231"})
    assert auto.detail.startswith("auto: no ROS 2 node seen") and "no micros_rt node" in auto.detail, auto
    assert check_ros2_visibility({"MICROS_RT_ROS2": "on"}).detail.startswith("on")
    assert check_ros2_visibility({"MICROS_RT_ROS2": "off"}).detail.startswith("off")
    bad = check_ros2_visibility({"MICROS_RT_ROS2": "maybe"})
    assert bad.failed and "MICROS_RT_ROS2=off" in bad.fix
