"""Static transform broadcasters as ROS 2 has them on the wire, in one process of .venv (no rospy node, no rclpy):

    dds_static_broadcasters.py --frames base_link:laser base_link:camera

One DDS writer per ``parent:child`` pair on ``rt/tf_static``, type ``tf2_msgs::msg::dds_::TFMessage_``,
transient_local, reliable, keep_last 1, no micros_rt tag (so the relay takes them as ROS 2 nodes' writers), each
with one TFMessage of that transform (translation x = its index + 1), as ROS 2's ``static_transform_publisher``
sends. rclpy from PyPI has no tf2_msgs (``ros-jazzy-tf2-msgs`` is not published there), so the type is the
ROS 1 Debian package's mapped by micros_rt's DDS rule, which is ROS 2's layout of tf2_msgs/TFMessage.
Emits ``ready`` once every writer has written; runs until killed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from micros_rt.cyclone import import_cyclonedds
from micros_rt.transports.dds.endpoints import DDSWriter
from micros_rt.transports.dds.participant import DDSParticipant, cyclone_config, domain_id_from_env
from micros_rt.transports.dds.types import dds_type_for

import_cyclonedds()
from cyclonedds.qos import Policy, Qos  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", nargs="+", required=True)
    args = ap.parse_args()
    participant = DDSParticipant(domain_id_from_env(), cyclone_config())
    mapped = dds_type_for(TFMessage)
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000), Policy.Durability.TransientLocal,
              Policy.History.KeepLast(1))
    writers = []
    for i, pair in enumerate(args.frames):
        parent, child = pair.split(":")
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.transform.translation.x = float(i + 1)
        t.transform.rotation.w = 1.0
        writer = DDSWriter(participant, "rt/tf_static", mapped, qos)
        writer.write_serialized(mapped.encode(TFMessage(transforms=[t])))
        writers.append(writer)
    sys.stdout.write(json.dumps({"event": "ready", "writers": [w.guid for w in writers]}) + "\n")
    sys.stdout.flush()
    while True:
        time.sleep(1.0)


if __name__ == "__main__":
    main()
