"""The core every transport shares, once: per-topic publications and subscriptions (:mod:`.publication`,
:mod:`.subscription`), the send queues between ``publish()`` and the transports (:mod:`.send_queue`), the one admission
path and delivery thread (:mod:`.delivery`, :mod:`.writers`), statistics (:mod:`.stats`), the endpoint
registry (:mod:`.registry`), process state (:mod:`.runtime`), the introspection API the tools read
(:mod:`.introspection`). TCPROS and rospy's internals are a transport (:mod:`micros_rt.transports.tcpros`).

Nothing here is public API: import from :mod:`micros_rt`.
"""
