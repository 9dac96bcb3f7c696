#!/bin/sh
# Build the real mqtt_client (ika-rwth-aachen/mqtt_client, its ROS 1 node) from its sources, for the benchmarks
# and measurements that run beside it (benchmarks/mqtt_cpu.py --real-client, benchmarks/mqtt_start_order.py).
# Opt-in: the test suite never needs it (it reads captured bytes, tests/fixtures/mqtt_client/).
#
#   benchmarks/build_mqtt_client.sh REPO OUT [COMMIT ...]
#
# REPO: a git repository of mqtt_client (a clone, a bare clone, or a URL that is then cloned bare into OUT/src.git:
# the only network access, and only when you give a URL). OUT: where the programs land, one directory per
# commit: OUT/<version>-<commit>/mqtt_client (the program; run it as a ROS node, its parameters under its private
# namespace, /mqtt_client by default). COMMITs: default the two releases the project tests against,
# 0649f99 (v2.3.0-8, ROS 1, the fixture mqtt_client-2.3.0-0649f99.json) and f9b53da (v1.1.0).
#
# How: mqtt_client is a nodelet built with catkin. Debian 12 has no catkin workspace for it, so this script does
# what catkin would: generates the package's message and service headers with gencpp, compiles src/MqttClient.cpp
# against Debian's roscpp, nodelet, topic_tools, paho-mqtt C++ and fmt, and links it with a main that does what
# `rosrun nodelet nodelet standalone mqtt_client/MqttClient` does (nodelet::Loader without the ROS API, the
# nodelet named after the node, ros::spin), the instance made directly instead of by pluginlib (Debian 12's
# pluginlib is ROS 2's, so PLUGINLIB_EXPORT_CLASS is defined empty). -O2, as a catkin release build; Boost's bind
# placeholders global, as ROS Noetic's headers expect of Boost >= 1.73. The Debian packages it needs (as root):
#   g++ pkgconf libroscpp-dev libstd-msgs-dev ros-std-msgs libtopic-tools-dev libnodeletlib-dev
#   libpaho-mqtt-dev libpaho-mqttpp-dev libfmt-dev python3-gencpp python3-genmsg
set -eu

if [ $# -lt 2 ]; then
    sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
REPO=$1
OUT=$(mkdir -p "$2" && cd "$2" && pwd)
shift 2
[ $# -gt 0 ] || set -- 0649f99 f9b53dad6af7ed15b1a1303bacb6c10055358d86

for pkg in g++ pkgconf libroscpp-dev libstd-msgs-dev ros-std-msgs libtopic-tools-dev libnodeletlib-dev \
           libpaho-mqtt-dev libpaho-mqttpp-dev libfmt-dev python3-gencpp python3-genmsg; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing="${missing:-} $pkg"
done
if [ -n "${missing:-}" ]; then
    echo "missing Debian packages:${missing}; install them (as root): apt-get install${missing}" >&2
    exit 1
fi

case "$REPO" in
    *://*|git@*)
        [ -d "$OUT/src.git" ] || git clone --bare --quiet "$REPO" "$OUT/src.git"
        GITDIR=$OUT/src.git ;;
    *)
        if [ -d "$REPO/.git" ]; then GITDIR=$REPO/.git; else GITDIR=$REPO; fi ;;
esac
git --git-dir="$GITDIR" rev-parse --verify -q HEAD >/dev/null || { echo "$REPO is not a git repository" >&2; exit 1; }

GENCPP="/usr/bin/python3 /usr/lib/gencpp/gen_cpp.py"
TEMPLATES=/usr/share/gencpp
STD_MSGS=/usr/share/std_msgs/msg

for commit in "$@"; do
    full=$(git --git-dir="$GITDIR" rev-parse --verify "$commit^{commit}")
    version=$(git --git-dir="$GITDIR" describe --tags --abbrev=0 "$full" 2>/dev/null | sed 's/^v//' || echo unknown)
    dir=$OUT/$version-$(echo "$full" | cut -c1-7)
    rm -rf "$dir"
    mkdir -p "$dir/src" "$dir/gen/pluginlib"
    git --git-dir="$GITDIR" archive "$full" | tar -x -C "$dir/src"
    # 2.x: two packages (mqtt_client, mqtt_client_interfaces); 1.x: one (mqtt_client, its messages inside)
    if [ -d "$dir/src/mqtt_client_interfaces" ]; then
        node=$dir/src/mqtt_client
        ifaces=$dir/src/mqtt_client_interfaces
        ifpkg=mqtt_client_interfaces
    else
        node=$dir/src
        ifaces=$dir/src
        ifpkg=mqtt_client
    fi
    for f in "$ifaces"/msg/*.msg "$ifaces"/srv/*.srv; do
        [ -f "$f" ] || continue
        $GENCPP "$f" -p "$ifpkg" -o "$dir/gen/$ifpkg" -e "$TEMPLATES" \
            -I "std_msgs:$STD_MSGS" -I "$ifpkg:$ifaces/msg" >/dev/null
    done
    # Debian 12's pluginlib is ROS 2's (no pluginlib/class_list_macros.h): the main below makes the instance itself,
    # so the plugin registration is not needed
    printf '#pragma once\n#define PLUGINLIB_EXPORT_CLASS(class_type, base_class_type)\n' \
        > "$dir/gen/pluginlib/class_list_macros.h"
    cat > "$dir/standalone_main.cpp" <<'EOF'
// What `nodelet standalone mqtt_client/MqttClient` does, with the instance made here rather than by pluginlib.
#include <boost/make_shared.hpp>
#include <mqtt_client/MqttClient.h>
#include <nodelet/loader.h>
#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "mqtt_client");
  ros::NodeHandle nh;
  boost::function<boost::shared_ptr<nodelet::Nodelet>(const std::string&)> create =
      [](const std::string&) { return boost::shared_ptr<nodelet::Nodelet>(new mqtt_client::MqttClient()); };
  nodelet::Loader loader(create);
  ros::M_string remappings = ros::names::getRemappings();
  nodelet::V_string my_argv(argv + 1, argv + argc);
  if (!loader.load(ros::this_node::getName(), "mqtt_client/MqttClient", remappings, my_argv)) return 1;
  ros::spin();
  return 0;
}
EOF
    # shellcheck disable=SC2046
    g++ -std=c++17 -O2 -DNDEBUG -DBOOST_BIND_GLOBAL_PLACEHOLDERS -include boost/bind.hpp -w -o "$dir/mqtt_client" \
        -I "$node/include" -I "$dir/gen" \
        "$node/src/MqttClient.cpp" "$dir/standalone_main.cpp" \
        $(pkg-config --cflags --libs roscpp topic_tools fmt) \
        -lnodeletlib -lbondcpp -lpaho-mqttpp3 -lpaho-mqtt3as -lstdc++fs
    echo "built $dir/mqtt_client ($version, $full)"
done
