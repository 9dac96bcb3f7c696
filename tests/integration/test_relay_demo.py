"""The README's two-robot relay demo (examples/relay_demo.py, run by scripts/relay_demo.sh) does what the README
shows: robot A's stock 1 kHz control topic and 30 Hz camera reach robot B's stock subscriber through the two
relays across the 40 Mbit/s tbf link, the camera at the export's max_rate, the relays' counters printed, and
nothing left behind (namespaces, their /tmp directory) or sent on eth0.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path
from typing import Dict, List

import pytest

import harness

pytestmark = pytest.mark.integration

DEMO = harness.REPO_ROOT / "examples" / "relay_demo.py"
SECONDS = 3


def counters(line: str) -> Dict[str, int]:
    """``received 4,962, sent 4,962, rate_capped 0`` -> {"received": 4962, ...}"""
    return {k: int(v.replace(",", "")) for k, v in re.findall(r"(\w+) ([\d,]+)", line.split(": ", 1)[1])}


def test_the_relay_demo_delivers_control_and_camera_at_b_and_cleans_up() -> None:
    proc = subprocess.Popen([harness.MICROS_RT_PYTHON, str(DEMO), "--seconds", str(SECONDS)], text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=dict(os.environ))
    try:
        out, _ = proc.communicate(timeout=150)
    except subprocess.TimeoutExpired:
        proc.terminate()  # the demo removes its namespaces on SIGTERM too
        out, _ = proc.communicate(timeout=60)
        raise AssertionError(f"the demo did not end within 150 s:\n{out}")
    print(out)
    assert proc.returncode == 0, out
    names = [f"robot_a_{proc.pid}", f"robot_b_{proc.pid}"]
    # the configurations are printed: they are the lesson
    assert "--- relay_robot_a.yaml" in out and "max_rate: 2" in out and "as: /camera/image" in out, out
    # every second, 1 kHz control at B (most of it: a loaded 2-core machine) and the camera
    seconds: List[re.Match[str]] = list(re.finditer(
        r"^ +\d+ s +/control +([\d,]+)/s +latency p50 +([\d.]+) ms +p99 +([\d.]+) ms +/camera/image +(\d+) frames/s$",
        out, re.M))
    assert len(seconds) == SECONDS, out
    assert all(int(m[1].replace(",", "")) >= 500 for m in seconds), out
    assert sum(int(m[4]) for m in seconds) > 0, out
    control = re.search(r"^  /control +([\d,]+) -> ([\d,]+), latency p50 ([\d.]+) ms", out, re.M)
    images = re.search(r"^  /camera/image +([\d,]+) -> ([\d,]+) frames", out, re.M)
    assert control is not None and images is not None, out
    published, delivered = (int(control[i].replace(",", "")) for i in (1, 2))
    assert published >= 0.5 * 1000 * SECONDS and delivered >= 0.95 * published, out
    # the camera crosses at the export's max_rate (2 Hz), not the 30 Hz it is published at
    published_images, delivered_images = (int(images[i].replace(",", "")) for i in (1, 2))
    assert published_images >= 10 * SECONDS and 0 < delivered_images <= 2 * SECONDS + 2, out
    # the relays' own counters: what A's relay sent and capped, what B's relay published
    lines = {m[1]: counters(m[0]) for m in re.finditer(r"^  (robot_\w+ (?:export|import) \S+) as \S+: .*$", out, re.M)}
    camera, control_out = lines["robot_a export /camera/image"], lines["robot_a export /control"]
    assert camera["rate_capped"] > 0 and delivered_images <= camera["sent"] <= 2 * SECONDS + 2, lines
    assert camera["received"] == camera["sent"] + camera["rate_capped"] + camera["no_reader"], lines
    assert control_out["sent"] >= delivered and control_out["rate_capped"] == 0, lines
    assert lines["robot_b import /robot_a/control"]["published"] >= delivered, lines
    # nothing left behind, nothing on eth0 (DDS and TCPROS stay inside the namespaces)
    netns = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=10).stdout.split()
    assert not set(names) & set(netns), netns
    assert f"removed namespaces {names[0]} and {names[1]}" in out, out
    assert not Path(f"/tmp/{names[0]}").exists()
    tx = re.search(r"^eth0 tx packets during the demo: (\d+)$", out, re.M)
    assert tx is not None and int(tx[1]) < 100, out  # a DDS or TCPROS leak would be thousands at 1 kHz
