"""``micros-rt doctor``: check the set-up a micros_rt node depends on, each failure with a one-line fix.

Checks: the ``MICROS_RT_*`` settings take their values (:mod:`micros_rt.settings`); the ROS master answers;
``ROS_IP``/``ROS_HOSTNAME`` resolve to this host and agree; which network interface and Cyclone configuration
micros_rt will use (the same functions the library uses: :mod:`micros_rt.transports.dds.participant`) and whether
multicast is on; ``ROS_DOMAIN_ID`` is valid; Cyclone starts with that configuration; the clocks of the graph's
micros_rt nodes agree with this one; shared memory, ROS 2 visibility and the ROS 2 helper; the YAML profile
named by ``MICROS_RT_QOS_PROFILE`` is valid. Exit code 0 only when every check passes.
"""

from __future__ import annotations

import ipaddress
import os
import re
import socket
import subprocess
import threading
import time
import urllib.parse
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Tuple

from . import CommandError
from ._args import ArgumentParser
from ._graphinfo import MICROS_RT, Master, master_uri, probe_all
from .. import settings
from ..exceptions import MicrosRtError, SettingError

__all__ = ["Check", "main", "run_checks", "interface_addresses", "judge_clocks"]

OK, FAIL, SKIP = "OK", "FAIL", "SKIP"


@dataclass(frozen=True)
class Check:
    """One check's outcome: ``status`` OK, FAIL or SKIP (not applicable; not a failure), what was found
    and, when it failed, the one line that fixes it."""

    name: str
    status: str
    detail: str
    fix: str = ""

    @property
    def failed(self) -> bool:
        return self.status == FAIL


def main(argv: List[str]) -> int:
    """``micros-rt doctor [-v]``."""
    parser = ArgumentParser(
        prog="micros-rt doctor", usage="%(prog)s [-v]",
        description="Check what micros_rt nodes depend on: the ROS master, ROS_IP/ROS_HOSTNAME, the network "
                    "interface and Cyclone DDS configuration micros_rt will use (and multicast), ROS_DOMAIN_ID, "
                    "that Cyclone starts, the clock offset of the graph's micros_rt nodes, and the profile in "
                    "MICROS_RT_QOS_PROFILE. Each failed check prints a one-line fix; the exit code is 0 only "
                    "when every check passes.")
    parser.add_argument("-v", "--verbose", action="store_true", help="also print the full Cyclone configuration")
    args = parser.parse_args(argv)
    checks = run_checks(os.environ)
    width = max(len(c.name) for c in checks)
    for c in checks:
        print(f"[{c.status:^4}] {c.name:<{width}}  {c.detail}")
        if c.fix:
            print(f"       {'':<{width}}  fix: {c.fix}")
    if args.verbose:
        from ..transports.dds.participant import cyclone_config

        try:
            print(f"\nCyclone configuration (later sources win):\n  {cyclone_config(os.environ)}")
        except Exception as exc:
            print(f"\nCyclone configuration: cannot be built ({exc})")
    failed = sum(c.failed for c in checks)
    print(f"\n{failed} of {len(checks)} checks failed" if failed else f"\nall {len(checks)} checks passed")
    return 1 if failed else 0


def run_checks(env: Mapping[str, str]) -> List[Check]:
    """Every check, in order; a check that cannot run because an earlier one failed says so."""
    master = check_master(env)
    domain = check_domain(env)
    return [check_settings(env), master, check_address(env), check_dds_network(env), domain,
            check_cyclone(env) if not domain.failed else
            Check("Cyclone DDS", SKIP, "not started: ROS_DOMAIN_ID is invalid"),
            check_clocks(env) if not master.failed else Check("clocks", SKIP, "not checked: no ROS master"),
            check_shared_memory(env), check_ros2_visibility(env), check_ros2_helper(env), check_profile(env)]


# --------------------------------------------------------------------------- checks

def check_settings(env: Mapping[str, str]) -> Check:
    """Every ``MICROS_RT_*`` variable of :mod:`micros_rt.settings` has a value it takes (``init_node`` refuses to
    start otherwise); other ``MICROS_RT_*`` names are listed (a typo sets nothing)."""
    others = settings.unknown(env)
    also = f"; not settings of micros_rt (a typo sets nothing): {', '.join(others)}" if others else ""
    try:
        settings.check(env)
    except SettingError as exc:
        return Check("settings", FAIL, f"{exc}{also}", "correct or unset the variable named (docs/troubleshooting.md#settings "
                     "lists every MICROS_RT_* setting and its values)")
    given = [s.name for s in settings.SETTINGS if s.text(env)]
    return Check("settings", OK, (f"set: {', '.join(given)}" if given else "every MICROS_RT_* setting at its "
                                  "default") + also)


def _value(setting: "settings.Setting[settings.T]", env: Mapping[str, str]) -> "settings.T":
    """``setting``'s value in ``env``; its default when the value is bad (:func:`check_settings` says so)."""
    try:
        return setting.get(env)
    except SettingError:
        return setting.unset


def check_master(env: Mapping[str, str]) -> Check:
    uri = master_uri(env)
    try:
        pid = Master(uri, timeout=3.0).call("getPid")
    except CommandError as exc:
        return Check("ROS master", FAIL, str(exc).split(";")[0],
                     "start roscore (or rosmaster --core), or export ROS_MASTER_URI=http://HOST:11311/ naming "
                     "the running master")
    return Check("ROS master", OK, f"{uri} answers (pid {pid})")


def interface_addresses() -> Dict[str, str]:
    """IPv4 address -> interface name of this host (``ip -4 -o addr show``)."""
    found = {"127.0.0.1": "lo"}
    try:
        out = subprocess.run(["ip", "-4", "-o", "addr", "show"], capture_output=True, text=True,
                             timeout=5).stdout
    except (OSError, subprocess.SubprocessError):
        return found
    for line in out.splitlines():
        parts = line.split()
        if "inet" in parts and len(parts) > 1:
            found[parts[parts.index("inet") + 1].split("/")[0]] = parts[1]
    return found


def _resolve(host: str) -> Optional[str]:
    try:
        return socket.gethostbyname(host)
    except (OSError, UnicodeError):
        return None


def _is_loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def _local(address: str, interfaces: Mapping[str, str]) -> bool:
    return _is_loopback(address) or address in interfaces


def check_address(env: Mapping[str, str], interfaces: Optional[Mapping[str, str]] = None) -> Check:
    """ROS_IP / ROS_HOSTNAME: resolvable, this host's, consistent with each other and with the master."""
    name = "ROS_IP/ROS_HOSTNAME"
    ifaces = interface_addresses() if interfaces is None else interfaces
    ros_ip, ros_host = env.get("ROS_IP", "").strip(), env.get("ROS_HOSTNAME", "").strip()
    if ros_ip:
        try:
            ipaddress.ip_address(ros_ip)
        except ValueError:
            return Check(name, FAIL, f"ROS_IP={ros_ip!r} is not an IP address",
                         "export ROS_IP=<an address of this host>, or put a name in ROS_HOSTNAME instead")
        if not _local(ros_ip, ifaces):
            return Check(name, FAIL, f"ROS_IP={ros_ip} is not an address of this host (it has "
                         f"{', '.join(sorted(ifaces))})", "export ROS_IP=<one of this host's addresses>")
    host_addr = None
    if ros_host:
        host_addr = _resolve(ros_host)
        if host_addr is None:
            return Check(name, FAIL, f"ROS_HOSTNAME={ros_host} does not resolve",
                         f"add {ros_host} to /etc/hosts (or DNS), or export ROS_IP=<this host's address> instead")
        if not _local(host_addr, ifaces):
            return Check(name, FAIL, f"ROS_HOSTNAME={ros_host} resolves to {host_addr}, not an address of this host",
                         "export ROS_HOSTNAME=<this host's name>, or ROS_IP=<this host's address>")
    if ros_ip and host_addr and host_addr != ros_ip:
        return Check(name, FAIL, f"ROS_IP={ros_ip} but ROS_HOSTNAME={ros_host} ({host_addr}): rospy advertises "
                     f"ROS_HOSTNAME, micros_rt's DDS follows ROS_IP",
                     "set only one of ROS_IP and ROS_HOSTNAME, or make them name the same address")
    address = ros_ip or host_addr
    if address is None:
        hostname = socket.gethostname()
        address = _resolve(hostname)
        if address is None:
            return Check(name, FAIL, f"neither is set and the host name {hostname!r} does not resolve",
                         "export ROS_IP=<this host's address> (127.0.0.1 for a single machine)")
        shown = f"neither set: nodes advertise the host name {hostname} ({address})"
    else:
        shown = f"nodes advertise {ros_ip or ros_host}" + (f" ({address})" if address != (ros_ip or ros_host) else "")
    master_host = urllib.parse.urlparse(master_uri(env)).hostname or "localhost"
    master_addr = _resolve(master_host)
    if master_addr is not None and not _local(master_addr, ifaces) and _is_loopback(address):
        return Check(name, FAIL, f"{shown}, a loopback address, but the master {master_host} is on another host: "
                     "its other nodes cannot reach this one", "export ROS_IP=<this host's address on the "
                     "master's network>")
    return Check(name, OK, shown)


def _user_network(uri: str) -> str:
    """The interface and multicast a user's CYCLONEDDS_URI sets (file, file:// URI or inline XML)."""
    texts = []
    for part in uri.split(","):
        part = part.strip()
        if part.startswith("<"):
            texts.append(part)
            continue
        path = urllib.parse.urlparse(part).path if part.startswith("file://") else part
        try:
            with open(path, encoding="utf-8") as f:
                texts.append(f.read())
        except OSError as exc:
            raise ValueError(f"CYCLONEDDS_URI names {part}, which cannot be read ({exc.strerror})") from None
    text = "\n".join(texts)
    iface = re.findall(r'<NetworkInterface\s[^>]*(?:name|address)\s*=\s*"([^"]+)"', text, flags=re.IGNORECASE)
    where = f"interface {iface[-1]}" if iface else "Cyclone's choice of interface"
    found = re.findall(r"<AllowMulticast>\s*([^<\s]+)\s*</AllowMulticast>", text, flags=re.IGNORECASE)
    if found:
        value = found[-1].lower()
        return f"{where}, multicast {'off' if value == 'false' else value}"
    if re.search(r'multicast\s*=\s*"false"', text, flags=re.IGNORECASE):
        return f"{where}, multicast off"
    return f"{where}, multicast on (Cyclone's default where the interface supports it)"


def check_dds_network(env: Mapping[str, str], interfaces: Optional[Mapping[str, str]] = None) -> Check:
    """Which interface and Cyclone configuration micros_rt will use, and multicast (as the library picks
    them: :func:`micros_rt.transports.dds.participant.cyclone_config`)."""
    from ..transports.dds import participant
    from ..exceptions import DDSUnavailableError

    name = "DDS network"
    ifaces = interface_addresses() if interfaces is None else interfaces
    try:
        participant.cyclone_config(env)
        lease = participant.lease_duration(env)
    except DDSUnavailableError as exc:
        if settings.SEND_BUFFER.name in str(exc):
            return Check(name, FAIL, str(exc),
                         "unset MICROS_RT_SEND_BUFFER (Cyclone's own send buffer) or give it a size such as 16kB, "
                         "only in a process whose DDS topics are all below HIGH")
        return Check(name, FAIL, str(exc), "unset MICROS_RT_LEASE_DURATION or give it 0.5..3600 seconds")
    sending = participant.send_buffer(env)
    chosen = f"lease {lease:g} s"
    if sending is not None:
        chosen += f", UDP send buffer {sending} B (MICROS_RT_SEND_BUFFER)"
    user = env.get("CYCLONEDDS_URI", "").strip()
    if user:
        try:
            network = _user_network(user)
        except ValueError as exc:
            return Check(name, FAIL, str(exc), "point CYCLONEDDS_URI at a readable Cyclone XML file, or unset it")
        return Check(name, OK, f"{network} (CYCLONEDDS_URI={user}, layered over micros_rt's defaults: "
                     f"{chosen})")
    address = participant._ros_address(env)
    if participant._is_loopback(env):
        bursts = "" if participant._shm_off(env) else " in bursts of 128 kB (what ROS 2 readers' buffers hold)"
        return Check(name, OK, f"interface lo ({address} is loopback): multicast off, unicast discovery on "
                     f"127.0.0.1, 63 KB fragments{bursts}, {chosen}")
    iface = ifaces.get(address, "no interface holds it")
    return Check(name, OK, f"interface {iface} ({address}): multicast on (Cyclone's default), {chosen}")


def check_domain(env: Mapping[str, str]) -> Check:
    from ..transports.dds.participant import domain_id_from_env
    from ..exceptions import DDSUnavailableError

    try:
        domain = domain_id_from_env(env)
    except DDSUnavailableError as exc:
        return Check("ROS_DOMAIN_ID", FAIL, str(exc),
                     "export ROS_DOMAIN_ID=0 (any integer 0..232, the same on every node that should talk)")
    given = "" if env.get("ROS_DOMAIN_ID", "").strip() else " (not set: the default)"
    return Check("ROS_DOMAIN_ID", OK, f"{domain}{given}")


def check_cyclone(env: Mapping[str, str]) -> Check:
    """Start a Cyclone participant with micros_rt's configuration (in this process) and close it."""
    from ..transports.dds.participant import DDSParticipant, cyclone_config, domain_id_from_env
    from ..exceptions import DDSUnavailableError

    try:
        domain = domain_id_from_env(env)
        p = DDSParticipant(domain, cyclone_config(env))
    except DDSUnavailableError as exc:
        return Check("Cyclone DDS", FAIL, str(exc), "fix CYCLONEDDS_URI (or unset it) and the interface named by "
                     "ROS_IP; micros_rt falls back to TCPROS until then")
    except ImportError as exc:
        return Check("Cyclone DDS", FAIL, f"cyclonedds cannot be imported ({exc})", "pip install cyclonedds")
    guid = p.guid
    p.close()
    return Check("Cyclone DDS", OK, f"a participant started on domain {domain} (guid {guid})")


def check_shared_memory(env: Mapping[str, str]) -> Check:
    """iceoryx2 and /dev/shm: a message through a shared-memory channel of this process, and what SIGKILLed
    processes left behind, reclaimed."""
    import platform

    from ..transports.shm import host

    if _value(settings.DISABLE_SHM, env):
        return Check("shared memory", SKIP, "turned off by MICROS_RT_DISABLE_SHM: micros_rt nodes of this host use "
                                            "DDS between them")
    reason = host.unavailable_reason(env)
    if reason is not None:
        if platform.machine() != "x86_64":
            return Check("shared memory", SKIP, f"{reason}; iceoryx2 has no wheel for {platform.machine()}: nodes "
                                                f"of this host use DDS between them")
        return Check("shared memory", FAIL, reason, "pip install iceoryx2 (in the environment micros_rt runs in) "
                     "and give /dev/shm room; until then nodes of this host use DDS between them")
    from ..transports.shm.channel import ShmLink, ShmWriter
    from std_msgs.msg import String

    done = threading.Event()
    try:
        t0 = time.monotonic()
        writer = ShmWriter("/micros_rt_doctor", lossless=False, latch=False, queue_size=1)
        channel = writer.open_channel("/micros_rt_doctor")
        link = ShmLink("/micros_rt_doctor", channel.name, String, header={}, qos=None,
                       put=lambda _msg, _ns, _link: done.set(), on_drop=lambda n: None, on_gone=lambda _link: None)
        link.start_thread()
        body = writer.prepare(String(data="doctor"))
        assert body is not None
        writer.send(body)
        crossed = done.wait(5.0)
        took = time.monotonic() - t0
        link.close()
        writer.close()
    except Exception as exc:
        problem = host.permission_problem()
        if problem is not None:
            return Check("shared memory", FAIL, f"a shared-memory channel failed: {problem}",
                         f"remove {host.iceoryx2_root()} (sudo rm -r): micros_rt makes it again for this user")
        return Check("shared memory", FAIL, f"a shared-memory channel failed: {exc}",
                     "check df -h /dev/shm (what fills it?); if it has room, report it with micros-rt doctor -v")
    if not crossed:
        return Check("shared memory", FAIL, "a message sent through a shared-memory channel did not arrive in 5 s",
                     "report it with the output of micros-rt doctor -v")
    free = os.statvfs("/dev/shm")
    import importlib.metadata as metadata

    return Check("shared memory", OK, f"iceoryx2 {metadata.version('iceoryx2')}; a message crossed a channel in "
                                      f"{took * 1e3:.0f} ms; /dev/shm "
                                      f"{free.f_bavail * free.f_frsize >> 20} MiB free; this user's iceoryx2 "
                                      f"directory {host.iceoryx2_root()}")


def check_ros2_visibility(env: Mapping[str, str]) -> Check:
    """When this host's nodes' topics are ROS 2 topics (MICROS_RT_ROS2, the profile's ros2:), and, with auto, whether
    the host's watcher has seen ROS 2 on the domain and which process watches."""
    try:
        mode = settings.ROS2.get(env)
    except SettingError as exc:
        return Check("ROS 2 visibility", FAIL, str(exc), "unset it (auto, the default), or export MICROS_RT_ROS2=off "
                     "(no ROS 2 nodes on this robot) or on")
    if mode == "off":
        return Check("ROS 2 visibility", OK, "off (MICROS_RT_ROS2): no DDS until a micros_rt peer on another "
                                             "host needs it; ROS 2 nodes do not see these nodes")
    if mode == "on":
        return Check("ROS 2 visibility", OK, "on (MICROS_RT_ROS2): every node has a DDS participant and its topics "
                                             "are ROS 2 topics from its start")
    from ..transports.dds.participant import domain_id_from_env
    from ..transports.dds.watch import gateway_paths, read_visible, watch_paths, watcher_pid

    try:
        domain = domain_id_from_env(env)
    except MicrosRtError as exc:
        return Check("ROS 2 visibility", FAIL, str(exc), "export ROS_DOMAIN_ID=0..232 (or unset it)")
    lock, marker = watch_paths(domain)
    pid = watcher_pid(lock)
    watching = f"watched by pid {pid}" if pid else "no micros_rt node of this host and user watches it now"
    try:
        with open(marker) as f:
            seen = len(f.read().split())
    except OSError:
        seen = 0
    visible = len(read_visible(gateway_paths(domain)[1]))
    now = (f"ROS 2 seen: {seen} participant(s) that are not micros_rt, so the watcher announces this host's nodes to "
           f"ROS 2; {visible} node(s) with a ROS 2 peer of their topics have DDS writers and readers of their own"
           if seen
           else "no ROS 2 node seen, so nodes make no DDS participant of their own (one node, the watcher, has one)")
    return Check("ROS 2 visibility", OK, f"auto: {now}; DDS domain {domain} {watching} (MICROS_RT_ROS2=on/off or "
                                         f"ros2: true/false in a profile fix it)")


def check_ros2_helper(env: Mapping[str, str]) -> Check:
    """The Python that micros_rt's ROS 2 helper runs (services and actions toward ROS 2): found, and rclpy imports."""
    from ..services.gateway import ros2_python

    name = "ROS 2 helper"
    needs = ("services and actions toward ROS 2 (advertise_service, service_client, offer_action_to_ros2, "
             "offer_ros2_action, a relay's ros2: services and actions)")
    if _value(settings.DISABLE_ROS2_SERVICES, env):
        return Check(name, SKIP, f"MICROS_RT_DISABLE_ROS2_SERVICES is set: no {needs}; topics reach ROS 2 without it")
    given = settings.ROS2_PYTHON.get(env)
    python = ros2_python(dict(env))
    if python is None:
        return Check(name, SKIP, f"no ROS 2 Python found (MICROS_RT_ROS2_PYTHON unset, no .venv-ros2): no {needs}, "
                                 f"they are served to ROS 1 only; topics reach ROS 2 without it")
    try:
        cp = subprocess.run([python, "-c", "import rclpy, rclpy.action"], capture_output=True, text=True, timeout=60,
                            stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return Check(name, FAIL, f"{python} cannot run ({exc}): no {needs}, they are served to ROS 1 only",
                     "point MICROS_RT_ROS2_PYTHON at the python of an installation with rclpy (e.g. "
                     ".venv-ros2/bin/python), or unset it" if given else "reinstall .venv-ros2 (scripts/setup.sh)")
    if cp.returncode != 0:
        why = (cp.stderr.strip().splitlines() or ["no output"])[-1]
        return Check(name, FAIL, f"{python} cannot import rclpy ({why}): no {needs}, they are served to ROS 1 "
                                 f"only",
                     "install rclpy there (pip install 'ros-jazzy-rclpy[fastrtps]'; scripts/setup.sh does it), or "
                     "point MICROS_RT_ROS2_PYTHON at another ROS 2 Python")
    return Check(name, OK, f"{python}: rclpy imports; {needs} go through it")


def check_clocks(env: Mapping[str, str]) -> Check:
    """Wall-clock offset of every micros_rt node of the graph against this host's."""
    master = Master(master_uri(env), timeout=3.0)
    try:
        pubs, subs = master.system_state()
    except CommandError as exc:
        return Check("clocks", SKIP, f"not checked: {exc}")
    names = {n for nodes in list(pubs.values()) + list(subs.values()) for n in nodes}
    return judge_clocks({r.name: (r.clock_offset, r.clock_error or 0.0) for r in probe_all(master, names).values()
                         if r.kind == MICROS_RT and r.clock_offset is not None})


def judge_clocks(offsets: Mapping[str, Tuple[float, float]]) -> Check:
    """node -> (its clock minus ours, +- uncertainty) in seconds: fails when an offset is surely over
    :data:`micros_rt.qos.CLOCK_SKEW_WARN_SECONDS`, where micros_rt subscribers start warning."""
    from ..qos import CLOCK_SKEW_WARN_SECONDS

    if not offsets:
        return Check("clocks", OK, "no micros_rt nodes in the graph to compare with")
    worst = max(offsets, key=lambda n: abs(offsets[n][0]) - offsets[n][1])
    offset, error = offsets[worst]
    text = (f"{len(offsets)} micros_rt node(s); largest offset {offset * 1e3:+.1f} ms (+- {error * 1e3:.1f} ms, "
            f"{worst})")
    if abs(offset) - error > CLOCK_SKEW_WARN_SECONDS:
        return Check("clocks", FAIL, text + f", over {CLOCK_SKEW_WARN_SECONDS:g} s",
                     "synchronise the hosts' clocks (chrony or NTP); source-time ordering and msg_valid_period "
                     "depend on them")
    return Check("clocks", OK, text)


def check_profile(env: Mapping[str, str]) -> Check:
    from ..exceptions import ProfileError
    from ..qos import QoSProfile

    path = settings.QOS_PROFILE.get(env)
    if not path:
        return Check("QoS profile", OK, "MICROS_RT_QOS_PROFILE not set (no profile)")
    try:
        profile = QoSProfile.load(path)
    except ProfileError as exc:
        return Check("QoS profile", FAIL, str(exc),
                     f"correct the line named (micros-rt profile check {path}), or unset MICROS_RT_QOS_PROFILE")
    return Check("QoS profile", OK, f"{path}: {len(profile.publishers)} publisher and {len(profile.subscribers)} "
                 "subscriber rules")
