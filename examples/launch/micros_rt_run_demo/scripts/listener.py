#!/usr/bin/env python3
"""rospy's tutorial listener; it prints which transport each message came by (DDS under micros_rt)."""

import rospy
from std_msgs.msg import String


def callback(msg):
    transport = msg._connection_header.get("transport", "TCPROS")
    rospy.loginfo("%s heard [%s] via %s", rospy.get_name(), msg.data, transport)


def listener():
    rospy.init_node("listener")
    rospy.Subscriber("chatter", String, callback)
    rospy.spin()


if __name__ == "__main__":
    listener()
