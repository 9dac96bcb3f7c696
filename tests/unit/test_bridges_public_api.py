"""Programs built on micros_rt (the relay, the MQTT bridge, the microcontroller bridge) import only its public
API: every module under micros_rt/bridges/ is parsed (imports inside functions and under TYPE_CHECKING
included, as tests/unit/test_structure.py reads them) and may name only the modules of :data:`PUBLIC`, its own
bridge's modules, and no private (``_name``) of another package."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, List, Tuple

import pytest

from unit.test_structure import _imports, _modules

#: The modules a program may import. The public API: the package (``micros_rt/__init__.py``'s ``__all__``),
#: its support modules and the exception tree, the QoS values and their YAML (profiles, the configuration
#: parsing a bridge's file shares with them, topic rules, links), and the extension module (the process's DDS
#: back end, info sections, send queues, XML-RPC with a timeout). A back end's own interface is the programs' too:
#: the one transport interface (``transports/base.py``) and each transport package's API that a bridge drives
#: (MQTT's connection, codecs and parameters; the microcontroller link, its wire, errors and link spec; the
#: DDS feed and names the relay uses).
PUBLIC = frozenset({
    "micros_rt",
    "micros_rt.exceptions",
    "micros_rt.log",
    "micros_rt.ratelimit",
    "micros_rt.rostypes",
    "micros_rt.cyclone",   # the one first import of cyclonedds (a relay reading DDS discovery goes through it)
    "micros_rt.extend",
    "micros_rt.qos",
    "micros_rt.qos.options",
    "micros_rt.qos.profiles",
    "micros_rt.qos.yamlconfig",
    "micros_rt.qos.topic_rules",
    "micros_rt.qos.links",
    "micros_rt.transports.base",
    "micros_rt.transports.mqtt",
    "micros_rt.transports.mqtt.backend",
    "micros_rt.transports.mqtt.client",
    "micros_rt.transports.mqtt.codec",
    "micros_rt.transports.mqtt.generations",
    "micros_rt.transports.mqtt.params",
    "micros_rt.transports.mcu",
    "micros_rt.transports.mcu.errors",
    "micros_rt.transports.mcu.link",
    "micros_rt.transports.mcu.spec",
    "micros_rt.transports.mcu.wire",
    "micros_rt.transports.dds.feed",
    "micros_rt.transports.dds.types",
    "micros_rt.ros2_types",   # ROS 1 classes of ROS 2-only types (public: ros2_message_class ...), their modules
    "micros_rt.services",   # the services' public package (docs/services.md): the relay's ros2: services use its helper
})
#: the command line's error type, for the programs' ``__main__`` modules (``micros-rt mqtt-bridge`` ...)
MAIN_ONLY = frozenset({"micros_rt.cli"})
BRIDGES = "micros_rt.bridges"


def _bridge_modules() -> Dict[str, Path]:
    return {name: path for name, path in _modules().items() if name == BRIDGES or name.startswith(BRIDGES + ".")}


def _allowed(module: str, target: str) -> bool:
    if target == BRIDGES or target.startswith(BRIDGES + "."):
        return True
    return target in PUBLIC or (module.endswith(".__main__") and target in MAIN_ONLY)


def non_public_imports(modules: Dict[str, Path]) -> List[str]:
    """Each bridge module's import of a micros_rt module outside :data:`PUBLIC`, as ``module imports target``."""
    mods = _modules()
    return sorted(f"{name} imports {target}" for name, path in modules.items()
                  for target in _imports(name, path, mods) if not _allowed(name, target))


def _imported_names(name: str, path: Path) -> List[Tuple[str, str]]:
    """(module, name) of every ``from X import name`` in the file, ``X`` resolved to an absolute name."""
    here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: List[Tuple[str, str]] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else [])) if node.level else str(node.module)
            found.extend((target, alias.name) for alias in node.names)
    return found


def private_names(modules: Dict[str, Path]) -> List[str]:
    """Each ``_name`` a bridge module takes from a micros_rt module outside its own bridge."""
    out: List[str] = []
    for name, path in modules.items():
        own = ".".join(name.split(".")[:3])    # micros_rt.bridges.<bridge>
        for target, imported in _imported_names(name, path):
            outside = target.startswith("micros_rt") and not (target == own or target.startswith(own + "."))
            if outside and imported.startswith("_") and imported != "__version__":
                out.append(f"{name} imports {target}.{imported}")
    return sorted(out)


def test_bridges_import_only_the_public_api() -> None:
    assert non_public_imports(_bridge_modules()) == []


def test_bridges_take_no_private_names_of_other_packages() -> None:
    assert private_names(_bridge_modules()) == []


def test_the_public_modules_exist() -> None:
    mods = _modules()
    assert sorted(m for m in PUBLIC | MAIN_ONLY if m not in mods) == []


@pytest.mark.parametrize("source,found", [
    ("from ...core.send_queue import SendQueue\n", ["micros_rt.bridges.relay.relay imports micros_rt.core.send_queue"]),
    ("def f():\n    from micros_rt.core import runtime\n",
     ["micros_rt.bridges.relay.relay imports micros_rt.core.runtime"]),
    ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import micros_rt.node\n",
     ["micros_rt.bridges.relay.relay imports micros_rt.node"]),
    ("import micros_rt\nfrom micros_rt.qos import TransportPriority\nfrom .config import RelayConfig\n", []),
])
def test_the_check_finds_a_non_public_import(tmp_path: Path, source: str, found: List[str]) -> None:
    path = tmp_path / "relay.py"
    path.write_text(source)
    assert non_public_imports({"micros_rt.bridges.relay.relay": path}) == found


def test_the_check_finds_a_private_name(tmp_path: Path) -> None:
    path = tmp_path / "config.py"
    path.write_text("from ...qos.profiles import _pairs, QoSProfile\nfrom .relay import _Export\n")
    assert private_names({"micros_rt.bridges.relay.config": path}) == [
        "micros_rt.bridges.relay.config imports micros_rt.qos.profiles._pairs"]

