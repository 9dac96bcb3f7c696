"""The one exception tree of micros_rt.

Every error micros_rt raises derives from :class:`MicrosRtError`. Errors from
foreign layers (cyclonedds, sockets, XML-RPC, YAML) are wrapped at the boundary
with ``raise ... from exc`` so the original stays attached.

Value errors in options are both :class:`MicrosRtError` and :class:`ValueError`
(or :class:`TypeError`), so ``except ValueError`` keeps working for callers who
treat micros_rt like any other Python library.
"""

from __future__ import annotations

__all__ = [
    "MicrosRtError",
    "QoSValueError",
    "QoSTypeError",
    "UnsupportedQoSError",
    "ProfileError",
    "DDSUnavailableError",
    "TypeMappingError",
    "NodeNotInitializedError",
    "PublishTimeoutError",
    "TransportError",
    "SettingError",
]


class MicrosRtError(Exception):
    """Base class of every error raised by micros_rt."""


class QoSValueError(MicrosRtError, ValueError):
    """A QoS option has a value outside what is allowed (the message names option, value, allowed)."""


class QoSTypeError(MicrosRtError, TypeError):
    """A QoS option has a value of the wrong type (the message names option, type, allowed types)."""


class UnsupportedQoSError(QoSValueError):
    """A QoS option that micros_rt deliberately refuses (e.g. ``data_centric_update=True``)."""


class ProfileError(MicrosRtError, ValueError):
    """A YAML QoS profile is malformed; the message names the file, the key and the line."""


class DDSUnavailableError(MicrosRtError):
    """Cyclone DDS could not be started; micros_rt falls back to TCPROS everywhere."""


class TypeMappingError(MicrosRtError):
    """A ROS 1 message class cannot be mapped to a DDS type."""


class NodeNotInitializedError(MicrosRtError):
    """A NodeHandle was used before :func:`micros_rt.init_node`."""


class PublishTimeoutError(MicrosRtError):
    """``publish()`` on a lossless topic (``queue_size=None``) stayed blocked longer than its bound
    because a subscriber does not keep up; the message names the topic and the subscribers."""


class TransportError(MicrosRtError):
    """A back end (DDS, ...) failed to send or receive; the message says which topic and why."""


class SettingError(MicrosRtError, ValueError):
    """A ``MICROS_RT_*`` environment variable has a bad value (the message names the variable, the value and
    what it takes; :mod:`micros_rt.settings`)."""
