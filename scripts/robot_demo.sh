#!/bin/bash
# Set up, then run a whole robot on this host under micros_rt's defaults (about 15 s): unmodified rospy scripts
# under `micros-rt run`, micros_rt API nodes, stock rospy, roscpp and rosbag, then rclpy nodes that join and leave;
# prints one table of every message, call and goal. Exits 1 when a message was lost.
#   scripts/robot_demo.sh [--domain N] [--no-cyclonedds-uri] [--json]
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO_ROOT"

scripts/setup.sh
exec .venv/bin/python tests/robot.py "$@"
