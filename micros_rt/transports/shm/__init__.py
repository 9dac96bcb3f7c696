"""Shared memory on one host (iceoryx2), negotiated in ``requestTopic`` as ``SHM``.

- :mod:`.host`: whether this process can share memory (the wheel, ``/dev/shm``) and with whom (the same
  machine, network and mount namespaces and Unix user), in words when not;
- :mod:`.channel`: one channel per publisher and subscriber, the publisher's writer and the subscriber's link.

iceoryx2 is imported only when a topic first negotiates SHM.
"""

from .host import host_identity, unavailable_reason

__all__ = ["host_identity", "unavailable_reason"]
