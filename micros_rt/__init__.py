"""micros_rt: real-time QoS and a DDS data plane for ROS 1 Python nodes, inside the ROS 1 graph.

The Python analogue of micROS RT: rospy's publish/subscribe API plus
``advertise_with_qos``/``subscribe_with_qos``; data between micros_rt nodes flows
over Cyclone DDS, with stock ROS nodes over TCPROS, negotiated per publisher.

>>> import micros_rt
>>> from std_msgs.msg import String
>>> micros_rt.init_node("talker")                                        # doctest: +SKIP
>>> nh = micros_rt.NodeHandle()                                          # doctest: +SKIP
>>> pub = nh.advertise_with_qos("chatter", String, 10, micros_rt.TransportPriority.HIGH)  # doctest: +SKIP
"""

import typing as _typing

from .exceptions import (
    DDSUnavailableError,
    MicrosRtError,
    NodeNotInitializedError,
    ProfileError,
    PublishTimeoutError,
    SettingError,
    QoSTypeError,
    QoSValueError,
    TransportError,
    TypeMappingError,
    UnsupportedQoSError,
)
from .transports.dds.publication import ForeignWriters
from .core.stats import PublisherStatistics, SubscriberStatistics
from .negotiation.hints import TransportHints
from .node import (
    DeadlineMissed,
    NodeHandle,
    NodeInfo,
    Publisher,
    Subscriber,
    init_node,
    is_shutdown,
    ok,
    node_info,
    shutdown,
    spin,
)
from .qos import (
    DURATION_MAX,
    DURATION_MIN,
    AdvertiseQoSOptions,
    QoSProfile,
    SubscribeQoSOptions,
    TransportPriority,
)

__all__ = [
    "AdvertiseQoSOptions",
    "DDSUnavailableError",
    "DURATION_MAX",
    "DURATION_MIN",
    "DeadlineMissed",
    "ForeignWriters",
    "MicrosRtError",
    "NodeHandle",
    "NodeInfo",
    "NodeNotInitializedError",
    "ProfileError",
    "PublishTimeoutError",
    "Publisher",
    "PublisherStatistics",
    "QoSProfile",
    "QoSTypeError",
    "QoSValueError",
    "ServiceClient",
    "SettingError",
    "ServiceServer",
    "ActionFromRos2",
    "ActionToRos2",
    "Ros2TypeError",
    "Subscriber",
    "SubscribeQoSOptions",
    "SubscriberStatistics",
    "TransportError",
    "TransportHints",
    "TransportPriority",
    "TypeMappingError",
    "UnsupportedQoSError",
    "init_node",
    "is_shutdown",
    "ok",
    "node_info",
    "ros2_action_class",
    "ros2_message_class",
    "ros2_service_class",
    "shutdown",
    "spin",
]
__version__ = "0.1.0"

if _typing.TYPE_CHECKING:   # the lazy names below, typed for users' type checkers
    from .ros2_types import Ros2TypeError, ros2_action_class, ros2_message_class, ros2_service_class

#: What NodeHandle's services and actions return, and the classes of ROS 2-only types, imported when first named
#: (a node without them never loads them: ``import micros_rt`` stays as light as before)
_LAZY = {"ServiceClient": ".services", "ServiceServer": ".services", "ActionFromRos2": ".actions",
         "ActionToRos2": ".actions", "Ros2TypeError": ".ros2_types", "ros2_action_class": ".ros2_types",
         "ros2_message_class": ".ros2_types", "ros2_service_class": ".ros2_types"}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'micros_rt' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])
