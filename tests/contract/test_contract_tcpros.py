"""The transport contract for TCPROS: the same checks as ``test_contract.py``, run by ``tcpros_child.py`` in a
micros_rt node of its own against this run's rosmaster (TcprosWriter and TcprosReader of one topic, rospy
connecting the node to itself over TCP on loopback)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

import harness
from contract.checks import CHECKS

pytestmark = pytest.mark.integration

CHILD = Path(__file__).resolve().parent / "tcpros_child.py"


def test_tcpros_keeps_the_transport_contract(ros_master: harness.RosMaster) -> None:
    cp = subprocess.run([harness.MICROS_RT_PYTHON, str(CHILD)], env=ros_master.env, capture_output=True, text=True,
                        timeout=120)
    results = [json.loads(line) for line in cp.stdout.splitlines() if line.startswith("{")]
    print("\n" + "\n".join(f"{r['check']}: {r['ok']} {r.get('seconds', '')} {r['error'][:300]}" for r in results))
    assert [r["check"] for r in results] == [c.__name__ for c in CHECKS], cp.stderr[-2000:]
    assert all(r["ok"] is not False for r in results), [r for r in results if r["ok"] is False]
    assert [r["check"] for r in results if r["ok"] is None] == ["check_malformed_wire_input_raises_a_micros_rt_error_in_words"]
    assert cp.returncode == 0, cp.stderr[-2000:]
