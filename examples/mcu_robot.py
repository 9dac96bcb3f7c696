#!/usr/bin/env python3
"""The ROS side of the microcontroller demo: a micros_rt node that talks to the board through mcu-bridge.

- hears the board's ``/imu`` (over DDS from the bridge) with a 0.5 s deadline and says when it is silent;
- sends ``/cmd_vel`` commands (the bridge forwards them to the board as datagrams with IP TOS AF41);
- serves ``/set_mode`` (std_srvs/SetBool), which the board calls through the bridge;
- calls the board's ``/mcu/reset`` (std_srvs/Trigger) once, as ``rosservice call`` would.

Run it beside ``micros-rt mcu-bridge --config examples/mcu_bridge.yaml`` and a board (or the C stand-in);
``examples/mcu_demo.py`` starts all of them.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from typing import Any

import rospy
from geometry_msgs.msg import Twist
from sensor_msgs.msg import Imu
from std_srvs.srv import SetBool, SetBoolResponse, Trigger

import micros_rt


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=5.0, help="seconds to run")
    args = ap.parse_args()
    micros_rt.init_node("mcu_robot")
    nh = micros_rt.NodeHandle()
    heard = [0]

    def on_imu(msg: Imu) -> None:
        heard[0] += 1
        if heard[0] % 100 == 1:
            print(f"robot: imu #{heard[0]} via {msg._connection_header['transport']}: "
                  f"accel z {msg.linear_acceleration.z:.2f}, frame {msg.header.frame_id}", flush=True)

    def on_silence(info: Any) -> None:
        print(f"robot: the board is silent: no /imu for {info.silent_for:.1f} s", flush=True)

    qos = dataclasses.replace(micros_rt.SubscribeQoSOptions(deadline=0.5), deadline_cb=on_silence)
    nh.subscribe_with_qos("/imu", Imu, on_imu, 100, qos)
    cmd = nh.advertise_with_qos("/cmd_vel", Twist, 10, micros_rt.TransportPriority.HIGH)

    def set_mode(req: Any) -> SetBoolResponse:
        print(f"robot: the board asked for set_mode({req.data})", flush=True)
        return SetBoolResponse(success=True, message="mode on" if req.data else "mode off")

    rospy.Service("/set_mode", SetBool, set_mode)
    try:
        rospy.wait_for_service("/mcu/reset", timeout=10.0)
        answer = rospy.ServiceProxy("/mcu/reset", Trigger)()
        print(f"robot: /mcu/reset answered success={answer.success} message={answer.message!r}", flush=True)
    except (rospy.ROSException, rospy.ServiceException) as exc:
        print(f"robot: /mcu/reset failed: {exc}", flush=True)
    end = time.monotonic() + args.duration
    i = 0
    while time.monotonic() < end and not micros_rt.is_shutdown():
        twist = Twist()
        twist.linear.x, twist.angular.z = 0.2, 0.1 * (i % 10)
        cmd.publish(twist)
        i += 1
        time.sleep(0.1)
    print(f"robot: heard {heard[0]} imu messages, sent {i} commands", flush=True)
    micros_rt.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
