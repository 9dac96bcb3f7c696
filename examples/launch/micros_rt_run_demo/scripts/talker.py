#!/usr/bin/env python3
"""rospy's tutorial talker, unchanged in spirit: nothing here knows about micros_rt."""

import rospy
from std_msgs.msg import String


def talker():
    rospy.init_node("talker")
    pub = rospy.Publisher("chatter", String, queue_size=10)
    rate = rospy.Rate(rospy.get_param("~rate", 10))
    n = 0
    while not rospy.is_shutdown():
        pub.publish(String(data="hello world %d" % n))
        n += 1
        rate.sleep()


if __name__ == "__main__":
    try:
        talker()
    except rospy.ROSInterruptException:
        pass
