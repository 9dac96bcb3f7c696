"""The tools' view of both worlds (issue 43, deliverable 4), as pure functions over a made-up master view and DDS
discovery: ROS 2 endpoints of a topic and their DDS links, what a relay carries, services and actions per side,
the graph's ROS 2 nodes. The integration tests (test_relay_ros2.py, test_relay_actions.py, test_migration.py) run
the same against real processes."""

from __future__ import annotations

from typing import Dict, List, Optional

from micros_rt.cli._bothcalls import action_rows, format_calls, service_rows
from micros_rt.cli._bothgraph import Both, Ros1View
from micros_rt.cli._bothinfo import carriage, dds_endpoints, dds_links
from micros_rt.cli._ddsgraph import DdsEndpoint, DdsView, Ros2Node
from micros_rt.cli._graphinfo import MICROS_RT, GraphSnapshot, NodeReport
from micros_rt.cli.graph import Ros2Side, to_dot
from micros_rt.cli.topic import format_info

GRAPH = "norunid@http://127.0.0.1:11311/"
P_R2, P_HELPER, P_MRT = "p-ros2", "p-helper", "p-mrt"


def ep(guid: str, participant: str, topic: str, type_name: str, writer: bool, tag: Optional[Dict[str, str]] = None,
       *, reliable: bool = True, transient_local: bool = False) -> DdsEndpoint:
    return DdsEndpoint(guid, participant, topic, type_name, writer, tag, reliable, transient_local)


def view(endpoints: List[DdsEndpoint]) -> DdsView:
    nodes = [Ros2Node("/", "estimator", P_R2, readers=[e.guid for e in endpoints if e.participant == P_R2
                                                       and not e.writer],
                      writers=[e.guid for e in endpoints if e.participant == P_R2 and e.writer]),
             Ros2Node("/", "relay_robot_services", P_HELPER,
                      readers=[e.guid for e in endpoints if e.participant == P_HELPER and not e.writer])]
    return DdsView(True, domain=7, participants={P_R2, P_HELPER, P_MRT}, endpoints=endpoints, nodes=nodes,
                   helpers={P_HELPER})


def both(dds: DdsView, **ros1: Dict[str, List[str]]) -> Both:
    r1 = Ros1View(True, uri="http://127.0.0.1:11311/", publishers=ros1.get("publishers", {}),
                  subscribers=ros1.get("subscribers", {}), services=ros1.get("services", {}),
                  types={t: ty for t, [ty] in ros1.get("types", {}).items()})
    return Both(r1, dds)


RELAY_TAG = {"graph": GRAPH, "node": "/relay_robot", "relay_ros2_import": "robot"}
RELAY = NodeReport("/relay_robot", "http://127.0.0.1:2/", MICROS_RT, info={"relay": {"graph": "robot", "ros2": [
    {"direction": "import", "kind": "topic", "name": "/estimate", "as": "/estimate", "received": 4, "published": 4},
    {"direction": "export", "kind": "service", "name": "/set_flag", "as": "/set_flag", "calls": 2, "failed": 0}]}})


def test_a_topic_s_ros2_endpoints_links_and_carriage() -> None:
    dds = view([ep("w1", P_R2, "rt/estimate", "std_msgs::msg::dds_::String_", True),
                ep("r1", P_MRT, "rt/estimate", "std_msgs::msg::dds_::String_", False, RELAY_TAG),
                ep("r2", P_R2, "rt/estimate", "std_msgs::msg::dds_::String_", False, transient_local=True),
                ep("x", P_MRT, "rt/estimate", "std_msgs::msg::dds_::String_", False, {"graph": "other@x", "node": "/o"})])
    b = both(dds)
    endpoints = dds_endpoints(dds, "/estimate", b.ours)
    assert [(e["node"], e["kind"], e["writer"]) for e in endpoints] == [
        ("/estimator", "ROS 2", True), ("/estimator", "ROS 2", False), ("/relay_robot", "relay", False)]
    links = {(link["publisher"], link["subscriber"]): link for link in dds_links(endpoints)}
    assert links[("/estimator", "/relay_robot")]["matched"] is True
    # a volatile writer does not serve a transient_local reader: said, not drawn as a link that carries
    assert links[("/estimator", "/estimator")]["reason"] == "the writer is volatile, the reader requires transient_local"
    carried = carriage({"/relay_robot": RELAY}, "/estimate")
    assert [(c["relay"], c["direction"], c["ros1"], c["ros2"]) for c in carried] == [
        ("/relay_robot", "from ROS 2", "/estimate", "/estimate")]
    assert carriage({"/relay_robot": RELAY}, "/other") == []


def test_a_ros2_only_topic_is_described() -> None:
    text = format_info({"topic": "/estimate", "side": "ROS 2", "type": "unknown", "ros2_types": ["std_msgs/msg/String"],
                        "publishers": [], "subscribers": [], "links": [], "carried": [], "dds_links": [],
                        "ros2_writers": [{"node": "/estimator", "kind": "ROS 2", "writer": True, "type":
                                          "std_msgs/msg/String", "qos": "reliable, volatile"}],
                        "ros2_readers": [], "dds": {"domain": 7, "wait": 1.5}})
    assert text.splitlines()[:7] == [
        "Type: std_msgs/msg/String (ROS 2)", "Side: ROS 2 only (not in the ROS 1 master)", "",
        "ROS 2 side (DDS rt/estimate, domain 7):", " writers:",
        " * /estimator  [ROS 2] std_msgs/msg/String; reliable, volatile", " readers: None"]


def test_services_and_actions_per_side() -> None:
    dds = view([
        # the rclpy node serves /ros2_trigger; the micros_rt relay's helper serves /set_flag; node plumbing
        ep("s1", P_R2, "rq/ros2_triggerRequest", "std_srvs::srv::dds_::Trigger_Request_", False),
        ep("s2", P_HELPER, "rq/set_flagRequest", "std_srvs::srv::dds_::SetBool_Request_", False),
        ep("s3", P_R2, "rq/estimator/get_parametersRequest", "rcl_interfaces::srv::dds_::GetParameters_Request_",
           False),
        ep("a1", P_R2, "rq/fib/_action/send_goalRequest", "test_msgs::action::dds_::Fibonacci_SendGoal_Request_",
           False)])
    b = both(dds, services={"/set_flag": ["/stock"], "/stock/get_loggers": ["/stock"]},
             publishers={"/fib/status": ["/relay_robot"], "/fib/feedback": ["/relay_robot"]},
             types={"/fib/feedback": ["test_msgs/FibonacciActionFeedback"]})
    rows = {r.name: r for r in service_rows(b, None)}
    assert sorted(rows) == ["/ros2_trigger", "/set_flag"], sorted(rows)   # node plumbing only with -a
    assert (rows["/set_flag"].side, rows["/set_flag"].ros1_servers, rows["/set_flag"].ros2_servers) == (
        "ROS 1+2", ["/stock"], ["/relay_robot (its ROS 2 helper)"])
    assert (rows["/ros2_trigger"].side, rows["/ros2_trigger"].ros2_type) == ("ROS 2", "std_srvs/srv/Trigger")
    assert len(service_rows(b, None, include_hidden=True)) == 4
    actions = action_rows(b, None)
    assert [(a.name, a.side, a.ros1_type, a.ros2_type, a.ros1_servers, a.ros2_servers) for a in actions] == [
        ("/fib", "ROS 1+2", "test_msgs/FibonacciAction", "test_msgs/action/Fibonacci", ["/relay_robot"],
         ["/estimator"])]
    assert format_calls(actions, "action").splitlines()[0].split() == [
        "ACTION", "SIDE", "TYPE", "ROS", "1", "SERVER", "ROS", "2", "SERVER"]


def test_the_graph_draws_ros2_nodes_and_what_the_relay_carries() -> None:
    dds = view([ep("w1", P_R2, "rt/estimate", "std_msgs::msg::dds_::String_", True),
                ep("r1", P_MRT, "rt/estimate", "std_msgs::msg::dds_::String_", False, RELAY_TAG)])
    snap = GraphSnapshot("http://127.0.0.1:11311/", {"/estimate": "std_msgs/String"}, {"/estimate": ["/relay_robot"]},
                         {}, {"/relay_robot": RELAY}, [])
    dot = to_dot(snap, ros2=Ros2Side(dds, both(dds).ours))
    assert '"r2:/estimator" [label="/estimator\\nROS 2 node"' in dot
    assert '"r2:/estimator" -> "t:/estimate" [label="ROS 2, reliable, volatile"' in dot
    assert '"t:/estimate" -> "n:/relay_robot" [label="relay from ROS 2\\n(into ROS 1 as /estimate)"' in dot
    assert '"n:/relay_robot" -> "r2service:/set_flag" [label="relay to ROS 2\\n(ROS 1 /set_flag)"' in dot
