"""The QoS layer of micros_rt: option values, their DDS mapping, compatibility checks and YAML profiles.

Pure logic: nothing here creates DDS entities or touches rospy.
"""

from micros_rt.qos.compatibility import (
    POLICY_NAMES,
    Compatibility,
    check_compatibility,
    describe_incompatible_policy,
)
from micros_rt.qos.enforcement import (
    CLOCK_SKEW_WARN_SECONDS,
    ClockSkewCheck,
    DeadlineMissed,
    DeadlineMonitor,
    SourceOrder,
    TimeFilter,
    is_expired,
)
from micros_rt.qos.mapping import (
    PUBLISH_BLOCK_TIMEOUT,
    RELIABLE_MAX_BLOCKING_TIME,
    UNBOUNDED_QUEUE_DEPTH,
    duration_ns,
    history_depth,
    is_lossless,
    plain_reader_qos,
    plain_writer_qos,
    reader_qos,
    writer_qos,
)
from micros_rt.qos.options import (
    DURATION_MAX,
    DURATION_MIN,
    AdvertiseQoSOptions,
    DeadlineMissedCallback,
    SubscribeQoSOptions,
    TransportPriority,
    priority_dscp,
    priority_socket_priority,
    priority_tos,
    to_seconds,
)
from micros_rt.qos.profiles import QoSProfile, merge_advertise, merge_subscribe

__all__ = [
    "CLOCK_SKEW_WARN_SECONDS",
    "PUBLISH_BLOCK_TIMEOUT",
    "ClockSkewCheck",
    "DeadlineMissed",
    "DeadlineMonitor",
    "SourceOrder",
    "TimeFilter",
    "is_expired",
    "is_lossless",
    "DURATION_MAX",
    "DURATION_MIN",
    "POLICY_NAMES",
    "RELIABLE_MAX_BLOCKING_TIME",
    "UNBOUNDED_QUEUE_DEPTH",
    "AdvertiseQoSOptions",
    "Compatibility",
    "DeadlineMissedCallback",
    "QoSProfile",
    "SubscribeQoSOptions",
    "TransportPriority",
    "check_compatibility",
    "describe_incompatible_policy",
    "duration_ns",
    "history_depth",
    "merge_advertise",
    "merge_subscribe",
    "plain_reader_qos",
    "plain_writer_qos",
    "priority_dscp",
    "priority_socket_priority",
    "priority_tos",
    "reader_qos",
    "to_seconds",
    "writer_qos",
]
