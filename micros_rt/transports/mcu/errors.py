"""The microcontroller link's errors, inside micros_rt's one exception tree."""

from __future__ import annotations

from micros_rt.exceptions import MicrosRtError, TransportError

__all__ = ["McuConfigError", "WireError", "DatagramTooLargeError", "McuServiceError"]


class McuConfigError(MicrosRtError, ValueError):
    """The bridge configuration is wrong; the message names the file, the line and the key."""


class WireError(MicrosRtError, ValueError):
    """Bytes from the microcontroller that do not form a valid datagram, frame or message.

    ``kind`` is a short, stable name for counters and rate-limited warnings (``not_msgpack``,
    ``unknown_stream``, ``missing_field``, ``bad_field``, ``bad_crc``, ``no_end``, ...); the message
    says what was wrong in words.
    """

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class DatagramTooLargeError(TransportError, ValueError):
    """A message encodes to more bytes than one datagram may carry (the link's ``mtu``).

    It is refused, never sent truncated; the message names the topic and both sizes.
    """

    def __init__(self, topic: str, size: int, mtu: int) -> None:
        super().__init__(
            f"{topic}: the message encodes to {size:,} bytes, more than the microcontroller link's "
            f"mtu of {mtu:,} bytes of payload per datagram; it was not sent (never truncated). "
            f"Send smaller messages, or raise 'mtu:' in the bridge configuration if every hop "
            f"to the board carries larger UDP payloads")
        self.topic = topic
        self.size = size
        self.mtu = mtu


class McuServiceError(TransportError):
    """A service call to or from the microcontroller failed (timeout, refused, bad answer)."""
