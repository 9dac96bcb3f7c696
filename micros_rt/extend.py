"""What programs built on micros_rt use beyond a node's API (the relay is one): the few pieces of the core a
program needs when :class:`~micros_rt.NodeHandle`, ``NodeHandle.subscribe_reader`` and
:class:`~micros_rt.Publisher` do not do the job. Prefer those; use these where a program drives a transport
itself (a DDS writer with a tag of its own, a reader it feeds).

- :func:`dds_backend`: this process's DDS back end (:class:`~micros_rt.transports.dds.backend.DDSBackend`:
  ``open_writer(spec, options)``, ``open_reader(...)``), or None when DDS did not start; call it after
  ``init_node``.
- :func:`register_info_section` / :func:`unregister_info_section`: a section of the program's own state in
  the node's ``microsRtInfo`` answer, which ``micros-rt graph`` and ``micros-rt topic`` show.
- :func:`sender_for` (a :class:`SendQueue`): put in front of a :class:`~micros_rt.transports.base.BackPressuredWriter`
  so that back-pressure on one topic never holds the caller, with a publication's rule (KEEP_LAST samples
  superseded before they left, and those older than the lifespan, are dropped and counted).
- :class:`TimeoutTransport`: an :mod:`xmlrpc.client` transport with a timeout of its own (rospy sets a
  process-wide socket timeout), for XML-RPC calls to other nodes and masters.
- :func:`latch_several`: a latching :class:`~micros_rt.Publisher` that gives a new TCPROS subscriber several
  latched messages (the relay's import of a topic with several transient_local ROS 2 writers: each one's last).
- :func:`register_negotiated_transport` (a :class:`NegotiatedTransport`: a protocol name and the makers of its
  :class:`PublicationSide` and :class:`SubscriptionSide`): a transport ``requestTopic`` negotiates as it does
  shared memory and DDS, offered on the topics made from then on and chosen by name in TransportHints
  (``TransportHints.from_names(["MINE", "TCPROS"])``) or a profile's ``transport_hints``;
  :func:`unregister_negotiated_transport` takes it back, name included. What its sides use is here too: an
  :class:`OfferJudge` (how a publication reads and judges an offer) giving a :class:`Verdict`,
  :class:`MalformedNegotiationError` for an offer or answer it cannot read, a :class:`PushReader` (depth
  :data:`UNBOUNDED_QUEUE_DEPTH` for ``queue_size=None``) its links hand messages to, and a :class:`PseudoLink` per
  peer in rospy's connection lists (:func:`attach_link` on the publisher's side, :func:`add_link` /
  :func:`remove_link` on the subscriber's). ``tests/contract/toy_negotiated.py`` is one, whole, importing only
  this module.

>>> import micros_rt
>>> from micros_rt.extend import dds_backend, register_info_section, sender_for
>>> micros_rt.init_node("my_program")                                        # doctest: +SKIP
>>> backend = dds_backend()                                                  # doctest: +SKIP
>>> writer = backend.open_writer(spec, micros_rt.AdvertiseQoSOptions())     # doctest: +SKIP
>>> sender = sender_for(writer, topic=spec.topic, queue_size=10, options=micros_rt.AdvertiseQoSOptions())  # doctest: +SKIP
>>> register_info_section("my_program", lambda: {"sent": sender.delayed})   # doctest: +SKIP
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, List

from .core.introspection import register_section as register_info_section
from .core.negotiated import register as register_negotiated_transport
from .core.negotiated import unregister as unregister_negotiated_transport
from .core.introspection import unregister_section as unregister_info_section
from .core.send_queue import SendQueue, sender_for
from .node import dds_backend
from .negotiation import MalformedNegotiationError, OfferJudge, Verdict
from .qos import UNBOUNDED_QUEUE_DEPTH
from .transports.base import PushReader
from .transports.links import PseudoLink, add_link, attach_link, remove_link
from .transports.negotiated import (NegotiatedTransport, PublicationHost, PublicationSide, SubscriptionHost,
                                    SubscriptionSide)
from .transports.tcpros.xmlrpc import TimeoutTransport

if TYPE_CHECKING:
    from .core.publication import Publisher

__all__ = ["MalformedNegotiationError", "NegotiatedTransport", "OfferJudge", "PseudoLink", "PublicationHost",
           "PublicationSide", "PushReader", "SendQueue", "SubscriptionHost", "SubscriptionSide", "TimeoutTransport",
           "UNBOUNDED_QUEUE_DEPTH", "Verdict", "add_link", "attach_link", "dds_backend", "latch_several",
           "register_info_section", "register_negotiated_transport", "remove_link", "sender_for",
           "unregister_info_section", "unregister_negotiated_transport"]


def latch_several(pub: "Publisher", lock: Any, messages: Callable[[], List[Any]]) -> None:
    """Latching ``pub`` (``advertise(..., latch=True)``) sends each new TCPROS subscriber every message of
    ``messages()``, oldest first, then its own latched message (the newest published). ``messages()`` is called
    under ``lock``, which the caller holds while it publishes on ``pub``. ROS 1 keeps one latched message per
    publisher; this keeps several in one (a relay's import of several transient_local ROS 2 writers)."""
    from .transports.tcpros import patches

    patches.replay_latched(pub.resolved_name, lock, messages)
