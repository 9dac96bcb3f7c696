"""Programs built on micros_rt (the relay, the MQTT bridge, the microcontroller bridge) import only its public
API: every module under micros_rt/bridges/ is parsed (imports inside functions and under TYPE_CHECKING
included, as tests/unit/test_structure.py reads them) and may name only the modules of :data:`PUBLIC`, its own
bridge's modules, and no private (``_name``) of another package. The command line (micros_rt/cli/) may reach
below the public API only where :data:`CLI_INTERNALS` says why. Neither imports a third-party library but ROS 1's
Python and YAML (:func:`third_party_imports`): DDS, shared memory, MQTT and ROS 2 are reached through micros_rt."""

from __future__ import annotations

import ast
import sys
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
    "micros_rt.cyclone",   # the one first import of cyclonedds
    "micros_rt.extend",
    "micros_rt.settings",   # the MICROS_RT_* variables (the relay reads the profile and send buffer asked)
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
#: the programs' shared ``__main__`` code (arguments, node, loop, exit codes), which raises the command's errors
PROGRAM = "micros_rt.bridges.program"
BRIDGES = "micros_rt.bridges"


CLI = "micros_rt.cli"
#: what the tools reach below the public API, each for a reason (a new one is a choice, written here)
CLI_INTERNALS = {
    "micros_rt.drop_in": "micros-rt run puts micros_rt under rospy's names",
    "micros_rt.negotiation.hints": "micros-rt run --hints",
    "micros_rt.core.introspection": "the microsRtInfo answer the graph tools read",
    "micros_rt.transports.tcpros.xmlrpc": "XML-RPC with a timeout to nodes and masters",
    "micros_rt.transports.dds.participant": "doctor and the ROS 2 view: the Cyclone configuration nodes use",
    "micros_rt.transports.dds.discovery": "the ROS 2 view: the one reader of DDS discovery",
    "micros_rt.transports.dds.watch": "doctor: the host's ROS 2 watcher",
    "micros_rt.transports.shm.host": "doctor: shared memory on this host",
    "micros_rt.transports.shm.channel": "doctor: a message through a shared-memory channel",
    "micros_rt.services.gateway": "doctor: the ROS 2 helper's interpreter",
}
#: ROS 1's Python, which programs live in, besides its message and service packages (``*_msgs``, ``*_srvs``)
ROS1 = frozenset({"rospy", "genpy", "genmsg", "roslib", "rosgraph"})
#: third-party packages a program may import besides ROS 1's: its files' format
THIRD_PARTY = frozenset({"yaml"})


def _bridge_modules() -> Dict[str, Path]:
    return {name: path for name, path in _modules().items() if name == BRIDGES or name.startswith(BRIDGES + ".")}


def _cli_modules() -> Dict[str, Path]:
    return {name: path for name, path in _modules().items() if name == CLI or name.startswith(CLI + ".")}


def cli_internal_imports(modules: Dict[str, Path]) -> List[str]:
    """Each CLI module's import of a micros_rt module that is neither public, the CLI's own, nor in
    :data:`CLI_INTERNALS`."""
    mods = _modules()
    return sorted(f"{name} imports {target}" for name, path in modules.items()
                  for target in _imports(name, path, mods)
                  if target not in PUBLIC and target not in CLI_INTERNALS and not target.startswith(CLI)
                  and not target.startswith(BRIDGES))


def third_party_imports(modules: Dict[str, Path]) -> List[str]:
    """Each import (anywhere in the file) of a package that is not the standard library, micros_rt, ROS 1's Python
    (:data:`ROS1`, message and service packages) or :data:`THIRD_PARTY`, as ``module imports package``."""
    out = set()
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets = [node.module]
            else:
                continue
            for target in targets:
                top = target.split(".")[0]
                if not (top in sys.stdlib_module_names or top == "micros_rt" or top in ROS1 or top in THIRD_PARTY
                        or top.endswith(("_msgs", "_srvs"))):
                    out.add(f"{name} imports {top}")
    return sorted(out)


def _allowed(module: str, target: str) -> bool:
    if target == BRIDGES or target.startswith(BRIDGES + "."):
        return True
    return target in PUBLIC or ((module.endswith(".__main__") or module == PROGRAM) and target in MAIN_ONLY)


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


def test_the_command_line_reaches_below_the_public_api_only_where_it_says_why() -> None:
    assert cli_internal_imports(_cli_modules()) == []
    mods = _modules()
    assert sorted(m for m in CLI_INTERNALS if m not in mods) == []


def test_programs_import_no_back_end_library_of_their_own() -> None:
    assert third_party_imports({**_bridge_modules(), **_cli_modules()}) == []


def test_the_check_finds_a_third_party_import(tmp_path: Path) -> None:
    path = tmp_path / "ros2.py"
    path.write_text("import rospy, yaml, json\nfrom std_msgs.msg import String\nfrom cyclonedds.core import Policy\n"
                    "def f():\n    import paho.mqtt.client\n    from .config import X\n")
    assert third_party_imports({"micros_rt.bridges.relay.ros2": path}) == [
        "micros_rt.bridges.relay.ros2 imports cyclonedds", "micros_rt.bridges.relay.ros2 imports paho"]


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

