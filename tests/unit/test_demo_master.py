"""scripts/demo.sh's choice of ROS master (examples/demo.py, issue 43): the master ROS_MASTER_URI names when it
answers, that very URI's port when it names this host and does not answer (so a second terminal with the same
ROS_MASTER_URI reaches the demo's master), a free port only without ROS_MASTER_URI. The old demo started a master
on a free port whenever the named one did not answer, and replaced the user's ROS_MASTER_URI by it."""

from __future__ import annotations

import importlib.util
from types import ModuleType

import harness




def _demo() -> ModuleType:
    spec = importlib.util.spec_from_file_location("micros_rt_demo", harness.REPO_ROOT / "examples" / "demo.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_named_master_is_used_when_it_answers_and_started_on_its_port_when_not() -> None:
    demo = _demo()
    asked = []

    def answers(uri: str) -> bool:
        asked.append(uri)
        return True

    assert demo.master_plan("http://127.0.0.1:11411/", answers) == (
        "http://127.0.0.1:11411/", None, "using the ROS master at http://127.0.0.1:11411/ (ROS_MASTER_URI)")
    assert asked == ["http://127.0.0.1:11411/"]
    uri, port, said = demo.master_plan("http://localhost:12345/", lambda _uri: False)
    assert (uri, port) == ("http://localhost:12345/", 12345) and "starting rosmaster there, on port 12345" in said
    # a named master of another host that does not answer: an error in words (port 0), no master of our own
    uri, port, said = demo.master_plan("http://robot-a.example:11311/", lambda _uri: False)
    assert port == 0 and "not on this host: start it, or unset ROS_MASTER_URI" in said, said
    # without ROS_MASTER_URI: the default master, else one on a free port, said with its URI
    uri, port, said = demo.master_plan(None, lambda _uri: False)
    assert port and uri == f"http://127.0.0.1:{port}" and f"ROS_MASTER_URI=http://127.0.0.1:{port}" in said
