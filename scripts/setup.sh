#!/bin/bash
# Idempotent setup for micros_rt on Debian 12 (run as root).
#   - Debian ROS 1 packages (rospy, rosmaster, rostopic, rosnode, messages) + capture/netns tools
#   - .venv       : /usr/bin/python3 venv WITH system site packages (rospy) + micros_rt[test] editable
#   - .venv-ros2  : plain venv with rclpy (Fast DDS) from PyPI, for ROS 2 peers. Never mix with rospy.
# Quiet unless something fails. Safe to run repeatedly; the second run does no network work.
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO_ROOT"

log() { echo "setup.sh: $*" >&2; }
die() { echo "setup.sh: ERROR: $*" >&2; exit 1; }

# Run a command quietly; on failure show its output and abort with a message.
quiet() {
    local what="$1"; shift
    local out
    if ! out="$("$@" 2>&1)"; then
        echo "$out" | tail -n 40 >&2
        die "$what failed: $*"
    fi
}

# ---------------------------------------------------------------- Debian packages
APT_PACKAGES=(
    python3-rospy python3-rosmaster python3-rostopic python3-rosnode
    python3-std-msgs python3-geometry-msgs python3-sensor-msgs ros-core
    python3-venv tcpdump nftables iproute2 python3-matplotlib python3-numpy
    python3-std-srvs python3-roslaunch python3-rosservice python3-dev gcc
    mosquitto mosquitto-clients libmsgpack-dev graphviz openssl
    python3-actionlib python3-actionlib-msgs python3-tf2-msgs python3-tf2-ros   # /tf_static through the relay
    g++ pkgconf libroscpp-dev libstd-srvs-dev    # the stock roscpp test peer, tests/peers/roscpp_setbool.cpp
)

missing=()
for p in "${APT_PACKAGES[@]}"; do
    status="$(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true)"
    [[ "$status" == "installed" ]] || missing+=("$p")
done
if ((${#missing[@]})); then
    [[ "$(id -u)" == 0 ]] || die "need root to apt-get install: ${missing[*]}"
    log "installing Debian packages: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    quiet "apt-get update" apt-get update -qq
    quiet "apt-get install" apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
for exe in /usr/bin/python3 /usr/bin/rosmaster /usr/bin/rostopic /usr/bin/rosnode /usr/sbin/mosquitto \
        /usr/bin/mosquitto_pub /usr/bin/dot /usr/bin/gcc /usr/bin/roslaunch; do
    [[ -x "$exe" ]] || die "$exe missing after package install"
done
quiet "stock rospy import check" env -u PYTHONPATH -u PYTHONHOME /usr/bin/python3 -c \
    "import rospy, rosgraph, rostopic, roslaunch, std_msgs.msg, std_srvs.srv, geometry_msgs.msg, sensor_msgs.msg, actionlib, actionlib_msgs.msg, tf2_msgs.msg, tf2_ros"

# ---------------------------------------------------------------- .venv (micros_rt, rospy visible)
VENV=.venv
STAMP="$VENV/.micros_rt_setup_stamp"
# the stamp also names how micros_rt is installed: a change of the pip command below reinstalls
want_stamp="$(sha256sum pyproject.toml | cut -d' ' -f1) editable_mode=compat"
if [[ ! -x "$VENV/bin/python" ]]; then
    log "creating $VENV"
    quiet "venv creation" /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
venv_ok() {
    [[ -f "$STAMP" && "$(cat "$STAMP")" == "$want_stamp" ]] || return 1
    env -u PYTHONPATH "$VENV/bin/python" - "$REPO_ROOT" <<'PY' >/dev/null 2>&1
import os, sys
import micros_rt, cyclonedds, yaml, pytest, mypy, rospy, paho.mqtt, msgpack  # noqa: F401
import platform
if platform.machine() == "x86_64":
    import iceoryx2  # noqa: F401  (shared memory on one host; no wheel elsewhere: micros_rt uses DDS there)
# editable install must point at this checkout (micros_rt may still be a namespace package)
want = os.path.join(os.path.realpath(sys.argv[1]), "micros_rt")
assert want in [os.path.realpath(p) for p in micros_rt.__path__], micros_rt.__path__
PY
}
if ! venv_ok; then
    log "installing micros_rt[test] into $VENV (editable)"
    rm -f "$STAMP"
    # editable_mode=compat: a path in a .pth file, not setuptools' import hook. The hook's module is imported by
    # every Python process of the venv at start-up (with pathlib, importlib.util, urllib.parse: ~16 ms of CPU per
    # process, measured against the system python's empty start), where an installed wheel costs nothing
    quiet "pip install -e .[test]" "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e '.[test]' \
        --config-settings editable_mode=compat
    echo "$want_stamp" > "$STAMP"
    venv_ok || die "$VENV installed but 'import micros_rt, cyclonedds, rospy, ...' fails in it"
fi
# An editable install compiles nothing, and with PYTHONDONTWRITEBYTECODE=1 (set on some machines, these
# included) every node start would compile micros_rt's ~12,000 lines again (measured: its modules import in
# 48 ms then, 20 ms from bytecode). Compile them as `pip install` of a wheel does; Python recompiles in
# memory a module whose source changed since, so a stale file costs time, never correctness.
quiet "bytecode compile" "$VENV/bin/python" -m compileall -q -j 0 micros_rt

# ---------------------------------------------------------------- .venv-ros2 (rclpy, NO system site packages)
VENV2=.venv-ros2
ROS2_PACKAGES=("ros-jazzy-rclpy[fastrtps]" ros-jazzy-std-msgs ros-jazzy-geometry-msgs ros-jazzy-sensor-msgs
               ros-jazzy-std-srvs ros-jazzy-test-msgs)
# Check inside the same loopback-only environment the tests use: init rclpy and create a node.
ros2_ok() {
    [[ -x "$VENV2/bin/python" ]] || return 1
    # a venv that sees the system site packages would mix rclpy and rospy
    grep -qi '^include-system-site-packages *= *false' "$VENV2/pyvenv.cfg" || return 1
    env -i PATH=/usr/bin:/bin HOME="${HOME:-/root}" \
        ROS_DOMAIN_ID=$((201 + $$ % 30)) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
        FASTRTPS_DEFAULT_PROFILES_FILE="$REPO_ROOT/tests/peers/fastdds_loopback.xml" \
        timeout 60 "$VENV2/bin/python" -c '
import rclpy, rclpy.action, std_msgs.msg, geometry_msgs.msg, sensor_msgs.msg, std_srvs.srv, test_msgs.srv, test_msgs.action
rclpy.init()
n = rclpy.create_node("micros_rt_setup_check")
n.destroy_node()
rclpy.shutdown()
' >/dev/null 2>&1
}
if ! ros2_ok; then
    if [[ -d "$VENV2" ]]; then
        if [[ -f "$VENV2/pyvenv.cfg" ]] && ! grep -qi '^include-system-site-packages *= *false' "$VENV2/pyvenv.cfg"; then
            log "$VENV2 sees system site packages (rospy clash): recreating it"
            rm -rf "$VENV2"
        fi
    fi
    if [[ ! -x "$VENV2/bin/python" ]]; then
        log "creating $VENV2"
        quiet "venv creation" /usr/bin/python3 -m venv "$VENV2"
    fi
    log "installing ${ROS2_PACKAGES[*]} into $VENV2"
    quiet "pip install rclpy" "$VENV2/bin/python" -m pip install -q --disable-pip-version-check "${ROS2_PACKAGES[@]}"
    ros2_ok || die "$VENV2: rclpy installed but 'rclpy.init(); create_node()' fails (try: rm -rf $VENV2)"
fi
