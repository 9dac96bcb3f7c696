"""The host's ROS 2 watcher (``auto`` visibility): one lock holder per host, user and domain, found from
/proc/locks, and micros_rt's participants told from everyone else's by their user data."""

from __future__ import annotations

import os

from micros_rt.transports.dds.watch import (PARTICIPANT_USER_DATA, Ros2Watch, is_micros_rt_participant, watch_paths,
                                            watcher_pid)

DOMAIN = 232  # no test run's own domain (1..220)


def test_paths_name_user_network_namespace_and_domain() -> None:
    lock, marker = watch_paths(DOMAIN)
    net = str(os.stat("/proc/self/ns/net").st_ino)
    assert lock.endswith(f"_u{os.getuid()}_n{net}_d{DOMAIN}.lock") and marker == lock[:-len(".lock")] + ".seen"
    assert watch_paths(DOMAIN - 1)[0] != lock


def test_participants_are_told_apart_by_user_data() -> None:
    assert is_micros_rt_participant(PARTICIPANT_USER_DATA)
    assert PARTICIPANT_USER_DATA.startswith(b"enclave=/;")  # what rmw reads stays there
    for foreign in (None, b"", b"enclave=/;", b"micros_rt=0;"):
        assert not is_micros_rt_participant(foreign)


def test_one_watcher_at_a_time_and_the_next_takes_over() -> None:
    first, second = Ros2Watch(DOMAIN, lambda: None), Ros2Watch(DOMAIN, lambda: None)
    try:
        assert first._take_lock()
        assert not second._take_lock() and not second.failed  # busy, not broken: it tries again next tick
        assert watcher_pid(first.lock_path) == os.getpid()
        first.close()
        assert second._take_lock()
        # a watcher whose DDS cannot start gives the watch up at once, and says so only once
        second.close()
        assert not first.poll() and first.failed and watcher_pid(first.lock_path) is None
    finally:
        first.close()
        second.close()
        os.unlink(first.lock_path)


def test_a_node_description_reads_back_as_written_and_the_visible_file_names_nodes_by_pid(tmp_path: "os.PathLike[str]"
                                                                                        ) -> None:
    from micros_rt.transports.dds.host_gateway import (EndpointDescription, NodeDescription, named_visible,
                                                       prune_descriptions, read_visible, remove_description,
                                                       write_description)

    prefix = os.path.join(str(tmp_path), "d.node")
    ends = [EndpointDescription("pub", "/a", "std_msgs/String", "992ce8a1687cec8c8bd883ec73ca41d1", "string data\n",
                                None, True, {"transport_priority": "HIGH"}, {"graph": "g", "node": "/n"}),
            EndpointDescription("sub", "/b", "std_msgs/String", "992ce8a1687cec8c8bd883ec73ca41d1", "string data\n",
                                10, False, None, {"graph": "g", "node": "/n"})]
    write_description(prefix, "/ns/n", ends)
    with open(f"{prefix}{os.getpid()}.json") as f:
        desc = NodeDescription.parse(f.read())
    assert (desc.pid, desc.node, list(desc.endpoints)) == (os.getpid(), "/ns/n", ends)
    assert len(set(desc.keys())) == 2
    with open(f"{prefix}999999999.json", "w") as f:  # a pid no process has: a node killed
        f.write("{}")
    open(f"{prefix}999999998.json.tmp", "w").close()  # a node killed while it wrote its description
    open(f"{prefix}{os.getpid()}.json.tmp", "w").close()  # a live node writing its own: not touched
    prune_descriptions(prefix)
    assert sorted(os.listdir(str(tmp_path))) == [f"d.node{os.getpid()}.json", f"d.node{os.getpid()}.json.tmp"]
    os.unlink(f"{prefix}{os.getpid()}.json.tmp")
    remove_description(prefix)
    assert not os.path.exists(f"{prefix}{os.getpid()}.json")

    visible = os.path.join(str(tmp_path), "d.visible")
    assert read_visible(visible) == {} and not named_visible(visible, "/ns/n")
    with open(visible, "w") as f:
        f.write(f"{os.getpid()} /ns/n\n1 /other\nbroken\n")
    assert read_visible(visible) == {os.getpid(): "/ns/n", 1: "/other"}
    assert named_visible(visible, "/ns/n") and not named_visible(visible, "/ns/m")


def test_importing_the_watch_loads_no_dds_library() -> None:
    """Every node but the host's watcher only looks at the watcher's files: the module it runs must not import
    cyclonedds (it did, through the discovery module's user-data parser: ~120 ms of CPU per node)."""
    import subprocess
    import sys

    code = ("import sys, micros_rt.transports.dds.watch, micros_rt.transports.dds.discovery\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'cyclonedds'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


def test_the_watcher_follows_participants_coming_and_going_reading_only_what_is_new() -> None:
    # a real Cyclone domain of this process (loopback): the watcher's view is kept from the samples discovery
    # brought since its last look (each deserialised once, taken from a reader of its own); one that leaves is
    # dropped, and a full read (participants(), its own reader) still sees everything
    import time

    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.qos import Policy, Qos

    from micros_rt.transports.dds.discovery import Discovery
    from micros_rt.transports.dds.participant import LOOPBACK_CONFIG, delete_entity

    domain = Domain(225, LOOPBACK_CONFIG)
    watcher = DomainParticipant(225)
    seen = Discovery(watcher, kinds=("participants:followed",))

    def guids(deadline_s: float, want: "set[str]", absent: "set[str]" = set()) -> "set[str]":
        deadline = time.monotonic() + deadline_s
        while True:
            now = {p.guid for p in seen.followed_participants()}
            if (want <= now and not absent & now) or time.monotonic() > deadline:
                return now
            time.sleep(0.02)

    try:
        assert str(watcher.guid) in guids(10, {str(watcher.guid)})
        other = DomainParticipant(225, qos=Qos(Policy.Userdata(b"enclave=/;")))
        other_guid = str(other.guid)
        now = guids(10, {other_guid})
        assert other_guid in now
        assert [p.user_data for p in seen.followed_participants() if p.guid == other_guid] == [b"enclave=/;"]
        # each sample is deserialised once: after a look, the view's own reader holds nothing more
        assert list(seen._reader("participants:followed")[0].take(N=100)) == []
        assert {p.guid for p in seen.followed_participants()} == now
        delete_entity(other)
        now = guids(10, set(), {other_guid})
        assert other_guid not in now and str(watcher.guid) in now
        assert {p.guid for p in seen.participants()} == now
    finally:
        seen.close()
        del watcher, domain
