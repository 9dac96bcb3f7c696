"""What a plug-in needs is ``micros_rt.extend``, and taking a plug-in back takes back all it added; the core names
no transport (its transports are behind the negotiated sides, built in by the node)."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Set

import pytest

from micros_rt.extend import (NegotiatedTransport, register_negotiated_transport,
                              unregister_negotiated_transport)
from micros_rt.negotiation import TransportHints
from micros_rt.negotiation.protocol import negotiated_protocols

ROOT = Path(__file__).resolve().parents[2]


def _micros_rt_imports(path: Path) -> Set[str]:
    found: Set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m == "micros_rt" or m.startswith("micros_rt.")}


def test_the_toy_transport_imports_nothing_of_micros_rt_but_extend() -> None:
    assert _micros_rt_imports(ROOT / "tests" / "contract" / "toy_negotiated.py") == {"micros_rt.extend"}


def test_unregistering_a_transport_takes_its_name_back_from_transport_hints() -> None:
    transport = NegotiatedTransport("PLUGGED", lambda host, refusal: None,  # type: ignore[arg-type,return-value]
                                    lambda host: None)  # type: ignore[arg-type,return-value]
    register_negotiated_transport(transport)
    try:
        assert "PLUGGED" in negotiated_protocols()
        assert TransportHints.from_names(["PLUGGED", "TCPROS"]).protocols == ("PLUGGED", "TCPROS")
    finally:
        unregister_negotiated_transport("PLUGGED")
    assert "PLUGGED" not in negotiated_protocols()
    with pytest.raises(ValueError, match="unknown transport 'PLUGGED'"):
        TransportHints.from_names(["PLUGGED", "TCPROS"])


def test_a_built_in_transport_cannot_be_unregistered() -> None:
    with pytest.raises(ValueError, match="built in"):
        unregister_negotiated_transport("SHM")
    assert "SHM" in negotiated_protocols()


def test_the_core_imports_no_module_of_any_one_transport() -> None:
    transports = ("dds", "shm", "mqtt", "mcu")
    offenders = []
    for path in sorted((ROOT / "micros_rt" / "core").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                parts = node.module.split(".")
                names = [a.name for a in node.names]
                if (any(p in transports for p in parts) or "cyclone" in parts
                        or (parts[-1] == "transports" and any(n in transports for n in names))):
                    offenders.append(f"{path.name}:{node.lineno}: {node.module} {names}")
            elif isinstance(node, ast.Import):
                offenders += [f"{path.name}:{node.lineno}: {a.name}" for a in node.names
                              if a.name.split(".")[0] in ("cyclonedds", "iceoryx2")]
    assert offenders == []
