"""Hosts in network namespaces of the test's own making, for robustness tests across a real network.

``Hosts(n)`` makes n namespaces joined by veth pairs to a bridge in a namespace of their own (nothing is
attached to the machine's own interfaces), addresses 10.78.T.1..n/24, every link at ``mtu`` (1500 unless told), a rosmaster on host 0, optional
nftables packet loss on every host's input (so both directions lose), and ``cut()``/``restore()`` of one
host's link. Everything is removed by ``down()``, also after a failure.
"""

from __future__ import annotations

import os
import subprocess
from typing import Dict, List, Optional

import harness


class Hosts:
    def __init__(self, n: int, *, loss_percent: int = 0, mtu: int = 1500, plain_bridge: bool = False) -> None:
        pid = os.getpid()
        self.plain_bridge = plain_bridge
        self.n = n
        self.loss_percent = loss_percent
        self.mtu = mtu
        self.net = f"10.78.{pid % 200 + 20}"
        self.names = [f"mrtH{i}_{pid}" for i in range(n)]
        self.bridge_ns = f"mrtBR_{pid}"
        self.master_port = 11311
        self.master: Optional["subprocess.Popen[bytes]"] = None

    @staticmethod
    def sh(*argv: str) -> None:
        subprocess.run(list(argv), check=True, capture_output=True, timeout=20)

    def link_name(self, i: int) -> str:
        """Host ``i``'s interface (its end of the veth pair to the bridge)."""
        return f"h{i}_{os.getpid()}"

    def ip(self, i: int) -> str:
        return f"{self.net}.{i + 1}"

    def up(self) -> "Hosts":
        pid = os.getpid()
        self.sh("ip", "netns", "add", self.bridge_ns)
        self.sh("ip", "-n", self.bridge_ns, "link", "add", "br0", "type", "bridge")
        if self.plain_bridge:  # a switch: bridged frames skip the firewall (no iptables, no reassembly there)
            self.sh("ip", "netns", "exec", self.bridge_ns, "sysctl", "-qw", "net.bridge.bridge-nf-call-iptables=0")
        self.sh("ip", "-n", self.bridge_ns, "link", "set", "br0", "up")
        for i, ns in enumerate(self.names):
            host_end, bridge_end = self.link_name(i), f"b{i}_{pid}"
            self.sh("ip", "netns", "add", ns)
            self.sh("ip", "link", "add", host_end, "mtu", str(self.mtu), "type", "veth", "peer", "name", bridge_end,
                    "mtu", str(self.mtu))
            self.sh("ip", "link", "set", host_end, "netns", ns)
            self.sh("ip", "link", "set", bridge_end, "netns", self.bridge_ns)
            self.sh("ip", "-n", self.bridge_ns, "link", "set", bridge_end, "master", "br0")
            self.sh("ip", "-n", self.bridge_ns, "link", "set", bridge_end, "up")
            self.sh("ip", "-n", ns, "addr", "add", f"{self.ip(i)}/24", "dev", host_end)
            self.sh("ip", "-n", ns, "link", "set", host_end, "up")
            self.sh("ip", "-n", ns, "link", "set", "lo", "up")
            if self.loss_percent:
                nft = ["ip", "netns", "exec", ns, "nft"]
                self.sh(*nft, "add", "table", "inet", "loss")
                self.sh(*nft, "add", "chain", "inet", "loss", "inp", "{ type filter hook input priority 0; }")
                self.sh(*nft, "add", "rule", "inet", "loss", "inp", "meta", "l4proto", "udp", "numgen", "random",
                        "mod", "100", "<", str(self.loss_percent), "drop")
        self.master = subprocess.Popen(
            ["ip", "netns", "exec", self.names[0], "/usr/bin/rosmaster", "--core", "-p", str(self.master_port)],
            env=self.env(0), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        harness.wait_until(self._master_up, 20, interval=0.2, message="rosmaster in host 0")
        return self

    def _master_up(self) -> bool:
        return subprocess.run(
            ["ip", "netns", "exec", self.names[0], "/usr/bin/python3", "-c",
             f"import xmlrpc.client as x; x.ServerProxy('{self.master_uri}').getPid('/t')"],
            capture_output=True, timeout=10).returncode == 0

    @property
    def master_uri(self) -> str:
        return f"http://{self.ip(0)}:{self.master_port}"

    def env(self, i: int) -> Dict[str, str]:
        env = harness.child_env({"ROS_MASTER_URI": self.master_uri, "ROS_IP": self.ip(i),
                                 "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", "0")})
        env.pop("CYCLONEDDS_URI", None)  # micros_rt's own default: the interface named by ROS_IP
        env["ROS_HOME"] = env["ROS_LOG_DIR"] = f"/tmp/{self.names[0]}"
        return env

    def run(self, i: int, argv: List[str]) -> List[str]:
        return ["ip", "netns", "exec", self.names[i], *argv]

    #: the classes a DSCP-honouring link serves first: AF41-43, CS5, EF, CS6, CS7 (TOS byte, mask 0xfc)
    PRIORITY_TOS = ("0x88", "0x90", "0x98", "0xa0", "0xb8", "0xc0", "0xe0")

    def shape_htb_dscp(self, i: int, rate: str = "40mbit") -> None:
        """Host ``i``'s egress at ``rate``, DSCP honoured as Wi-Fi WMM or a DiffServ router does: htb with a
        priority class (1:10, :data:`PRIORITY_TOS`) and a default one (1:20), each a 50 ms pfifo."""
        tc = ["ip", "netns", "exec", self.names[i], "tc"]
        dev = self.link_name(i)
        self.sh(*tc, "qdisc", "add", "dev", dev, "root", "handle", "1:", "htb", "default", "20")
        self.sh(*tc, "class", "add", "dev", dev, "parent", "1:", "classid", "1:1", "htb", "rate", rate)
        for cls, prio in (("1:10", "0"), ("1:20", "1")):
            self.sh(*tc, "class", "add", "dev", dev, "parent", "1:1", "classid", cls, "htb", "rate", "20mbit",
                    "ceil", rate, "prio", prio)
            self.sh(*tc, "qdisc", "add", "dev", dev, "parent", cls, "pfifo", "limit", "166")  # 50 ms of 1,500 B
        for tos in self.PRIORITY_TOS:
            self.sh(*tc, "filter", "add", "dev", dev, "parent", "1:", "protocol", "ip", "prio", "1", "u32", "match",
                    "ip", "tos", tos, "0xfc", "flowid", "1:10")

    def class_bytes(self, i: int) -> Dict[str, int]:
        """Bytes each htb class of host ``i``'s link has sent (``tc -s class show``)."""
        out = subprocess.run(["ip", "netns", "exec", self.names[i], "tc", "-s", "class", "show", "dev",
                              self.link_name(i)], capture_output=True, text=True, timeout=20, check=True).stdout
        found: Dict[str, int] = {}
        current = None
        for line in out.splitlines():
            words = line.split()
            if words[:2] == ["class", "htb"]:
                current = words[2]
            elif current and words[:1] == ["Sent"]:
                found[current] = int(words[1])
                current = None
        return found

    def cut(self, i: int) -> None:
        self.sh("ip", "-n", self.bridge_ns, "link", "set", f"b{i}_{os.getpid()}", "down")

    def restore(self, i: int) -> None:
        self.sh("ip", "-n", self.bridge_ns, "link", "set", f"b{i}_{os.getpid()}", "up")

    def down(self) -> None:
        if self.master is not None and self.master.poll() is None:
            self.master.terminate()
            try:
                self.master.wait(5)
            except subprocess.TimeoutExpired:
                self.master.kill()
        harness.delete_netns([*self.names, self.bridge_ns])
