"""TCPROS, ROS 1's own transport, as a micros_rt transport: rospy's Publisher and Subscriber behind the writer
and reader of :mod:`micros_rt.transports.base` (:mod:`.writer`, :mod:`.reader`), and rospy's patches
(:mod:`.patches`: protocol negotiation in ``requestTopic``, DDS and SHM links in rospy's connection lists, the
registration-race fixes, master restarts), the one place micros_rt reaches into ``rospy.impl``."""

from .reader import TcprosReader
from .writer import TcprosWriter
from .xmlrpc import TimeoutTransport

__all__ = ["TcprosReader", "TcprosWriter", "TimeoutTransport"]
