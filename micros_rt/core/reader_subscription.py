"""A subscription fed by one transport reader a program opened itself (the microcontroller link's UDP reader).

Same delivery thread, one admission path (time filter, lifespan), deadline monitor, queue_size rule and
statistics as every topic's subscription (:mod:`.subscription`); only its input differs: no registration with
the master, no DDS reader, no TCPROS link, just the reader the program hands over. Programs reach it through
:meth:`micros_rt.NodeHandle.subscribe_reader`.
"""

from __future__ import annotations

import math
from typing import Callable, Optional, Type

import genpy

from ..negotiation import TransportHints
from ..qos import SubscribeQoSOptions
from ..transports.base import PushReader
from .subscription import _Subscription

__all__ = ["OpenReader", "ReaderSubscription"]

#: ``(depth, wake) -> reader``: opens the reader with the subscription's queue depth (None: unbounded) and
#: the callable its I/O thread calls after each message.
OpenReader = Callable[[Optional[int], Callable[[], None]], PushReader]


class ReaderSubscription(_Subscription):
    """One reader's messages through the core's admission path to the callbacks (see the module docstring)."""

    def __init__(self, name: str, data_class: Type[genpy.Message], open_reader: OpenReader,
                 queue_size: Optional[int], options: Optional[SubscribeQoSOptions], *, graph: str,
                 lifespan: float = math.inf) -> None:
        super().__init__(name, data_class, queue_size, options, TransportHints().tcp(), tag={}, graph=graph,
                         lifespan=lifespan)
        self.source = open_reader(self.depth, self.inbox.wake)
        self.pushed = (self.source,)

    def start(self) -> None:
        """Start the delivery thread; nothing registers anywhere."""
        self.thread.start()
