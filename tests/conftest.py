"""Shared fixtures: real rosmaster, per-run DDS domain, loopback-only DDS, peer processes.

Fixtures
  dds_domain      (session)  int ROS_DOMAIN_ID for this run (1 + pid % 200); also in os.environ
  ros_master      (session)  harness.RosMaster: .uri .port .env .pid, shared by the whole run
  fresh_master    (function) harness.RosMaster private to one test, .restart() keeps the port
  spawn           (function) harness.Spawner: spawn(argv, env=None, *, name=None, cwd=None) -> Peer;
                             env defaults to ros_master.env; every peer is stopped at test end

At import time (before any test creates a DDS participant) this module points the in-process
Cyclone DDS and Fast DDS at the loopback-only configs, so nothing leaves on the LAN.

Markers, by directory: ``unit`` (pure logic, no process), ``contract`` (every transport against one contract),
``integration`` (real rosmaster, peers, hosts); ``smoke``: the integration tests of :data:`SMOKE`, one per transport
and per program. ``scripts/test.sh --fast`` runs ``not integration or smoke`` (the edit loop's tier, < 3 min on 2
cores); ``scripts/test.sh`` runs everything.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Iterator, List, Optional

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import harness  # noqa: E402

_DOMAIN_ID = int(os.environ.get("MICROS_RT_TEST_DOMAIN_ID") or harness.dds_domain_id_for_pid())
# In-process use (micros_rt/cyclonedds inside the pytest process): loopback DDS, our own domain.
os.environ.update(harness.dds_env(_DOMAIN_ID))
for _k in ("ROS_HOSTNAME",):
    os.environ.pop(_k, None)
os.environ["ROS_IP"] = "127.0.0.1"


#: One integration test per transport and per program: with the unit and contract tests (and the package's doctests,
#: tests/unit/test_doctests.py), the fast tier. tests/unit/test_test_tiers.py checks that each still exists.
SMOKE = (
    "tests/integration/test_ros1_interop.py::test_stock_talker_heard_by_micros_rt_listener",          # TCPROS
    "tests/integration/test_dds_plane.py::test_micros_rt_pair_uses_dds_not_tcp",                      # DDS
    "tests/integration/test_shm.py::test_shm_tcpros_and_dds_on_one_topic_each_message_once",          # shared memory
    "tests/integration/test_ros2_interop.py::test_rclpy_talker_to_micros_rt_listener[std_msgs/String]",  # ROS 2
    "tests/integration/test_ros2_auto.py::test_a_node_offering_a_service_starts_no_helper_until_a_ros2_node_comes_and_the_helper_is_no_ros2_node",
    "tests/integration/test_services.py::test_rclpy_client_calls_micros_rt_server",                   # services
    "tests/integration/test_actions.py::test_actionlib_client_drives_rclpy_server",                   # actions
    "tests/integration/test_cli_run.py::test_an_unmodified_actionlib_client_and_server_both_under_run",  # micros-rt run
    "tests/integration/test_relay.py::test_stock_cpp_and_python_topics_cross_to_another_graph",       # relay
    "tests/integration/test_mqtt_bridge.py::test_talker_to_mosquitto_sub_as_json_and_text_and_mosquitto_pub_69_to_listener",
    "tests/integration/test_mcu_bridge.py::test_imu_stream_at_100_hz_heard_by_micros_rt_listener_and_rostopic_echo",
)


def pytest_configure(config: pytest.Config) -> None:
    for name, what in (("env", "env(VAR=value, ..., why=...): the module runs with these settings instead of the "
                               "defaults users get (applied by the module-scoped fixture _module_env)"),
                       ("unit", "pure logic, no process (tests/unit)"),
                       ("contract", "every transport against one contract (tests/contract)"),
                       ("smoke", "one integration test per transport and per program (conftest.SMOKE)")):
        config.addinivalue_line("markers", f"{name}: {what}")


def pytest_collection_modifyitems(config: pytest.Config, items: List[pytest.Item]) -> None:
    smoke = set(SMOKE)
    for item in items:
        kind = Path(str(item.fspath)).parent.name
        if kind in ("unit", "contract", "integration"):
            item.add_marker(kind)
        if item.nodeid in smoke or item.nodeid.split("[")[0] in smoke:
            item.add_marker("smoke")


@pytest.fixture(scope="module", autouse=True)
def _module_env(request: pytest.FixtureRequest) -> Iterator[None]:
    """A module marked ``pytest.mark.env(VAR=value, ..., why="...")`` runs with those settings, in this process
    and in every child started from ``ros_master.env`` (the session's master, changed in place for the module);
    everything else runs the defaults users get. ``why`` is required: a mode users do not get needs a reason."""
    marker = request.node.get_closest_marker("env")
    if marker is None:
        yield
        return
    settings = dict(marker.kwargs)
    why = settings.pop("why", "")
    assert why, f"{request.node.nodeid}: pytest.mark.env needs why=... (why this module leaves the defaults)"
    master = request.getfixturevalue("ros_master")
    saved = {k: (os.environ.get(k), master.env.get(k)) for k in settings}
    os.environ.update(settings)
    master.env.update(settings)
    try:
        yield
    finally:
        for key, (env_value, master_value) in saved.items():
            for target, value in ((os.environ, env_value), (master.env, master_value)):
                if value is None:
                    target.pop(key, None)
                else:
                    target[key] = value


@pytest.fixture(scope="session")
def dds_domain() -> int:
    """This run's DDS domain id (also set as ROS_DOMAIN_ID in os.environ and in every child env)."""
    os.environ["ROS_DOMAIN_ID"] = str(_DOMAIN_ID)
    return _DOMAIN_ID


@pytest.fixture(scope="session")
def ros_master(dds_domain: int, tmp_path_factory: pytest.TempPathFactory) -> Iterator[harness.RosMaster]:
    """One real rosmaster for the whole run; sets ROS_MASTER_URI in os.environ for in-process nodes."""
    master = harness.RosMaster(workdir=tmp_path_factory.mktemp("ros_master"), domain_id=dds_domain)
    master.start()
    old_uri = os.environ.get("ROS_MASTER_URI")
    os.environ["ROS_MASTER_URI"] = master.uri
    try:
        yield master
    finally:
        master.cleanup()
        if old_uri is None:
            os.environ.pop("ROS_MASTER_URI", None)
        else:
            os.environ["ROS_MASTER_URI"] = old_uri


@pytest.fixture
def fresh_master(dds_domain: int, tmp_path: Path) -> Iterator[harness.RosMaster]:
    """A rosmaster private to this test (its own port); ``restart()`` stops and starts it on the same port.

    Does not touch os.environ: pass ``fresh_master.env`` to children.
    """
    master = harness.RosMaster(workdir=tmp_path / "ros_master", domain_id=dds_domain)
    master.start()
    try:
        yield master
    finally:
        master.cleanup()


@pytest.fixture
def spawn(request: pytest.FixtureRequest) -> Iterator[harness.Spawner]:
    """Start peer processes; all are stopped (SIGINT, SIGTERM, SIGKILL; bounded) when the test ends."""

    class _Spawner(harness.Spawner):
        def __call__(self, argv, env=None, *, name=None, cwd=None):  # type: ignore[no-untyped-def]
            if env is None and self.default_env is None:
                self.default_env = dict(request.getfixturevalue("ros_master").env)
            return super().__call__(argv, env, name=name, cwd=cwd)

    spawner: Optional[harness.Spawner] = _Spawner()
    assert spawner is not None
    try:
        yield spawner
    finally:
        spawner.close()
