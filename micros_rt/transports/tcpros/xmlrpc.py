"""An XML-RPC client transport with a timeout of its own (negotiation, the master watch, the CLI's probes)."""

from __future__ import annotations

import xmlrpc.client
from typing import Any

__all__ = ["TimeoutTransport"]


class TimeoutTransport(xmlrpc.client.Transport):
    # rospy sets a process-wide socket timeout for this call; a per-connection
    # timeout keeps user sockets out of it.
    def __init__(self, timeout: float) -> None:
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host: Any) -> Any:
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn
