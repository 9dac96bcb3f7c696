"""Whether a shared-memory offer comes from the node it names (issue 46).

Anyone who reaches a node's XML-RPC port can call ``requestTopic`` with any caller id. A TCPROS link costs a
forger a socket the publisher closes when it goes quiet; an SHM channel costs the publisher memory in /dev/shm,
a port and, once attached, the lossless wait of its publish(). So before a channel is made the publisher asks
the ROS master where the named node runs (``lookupNode``) and that node its process id (``getPid``), and
believes the offer only when that process is the offer's ``pid``. A caller unknown to the master, or a pid
that is not the named node's, is refused in words, and the subscriber it names keeps its link.

Import-light: no iceoryx2. A believed (caller, pid) is remembered, so a real subscriber pays the two calls
once per publisher process, not per topic.
"""

from __future__ import annotations

import collections
import threading
import xmlrpc.client
from typing import Any, Callable, Optional, Tuple

import rosgraph

from ..tcpros.patches import caller_id, short
from ..tcpros.xmlrpc import TimeoutTransport

__all__ = ["OfferVetting", "vetting"]

#: How long each of the two calls may take (a master or subscriber that does not answer: the offer is refused,
#: and the link takes the subscriber's next protocol, DDS or TCPROS, for good). Both together stay within the
#: subscriber's 10 s for requestTopic. 2 s was too short for a host starting 60 nodes at once: 1 and 3 of them (two
#: runs) then linked over DDS, each with a participant of its own; none in three runs with 4.5 s.
CALL_TIMEOUT = 4.5


def _ask(uri: str, method: str, *args: Any) -> Any:
    proxy = xmlrpc.client.ServerProxy(uri, transport=TimeoutTransport(CALL_TIMEOUT))
    answer: Any = getattr(proxy, method)(caller_id(), *args)
    code, msg, value = answer
    if code != 1:
        raise LookupError(str(msg))
    return value


class OfferVetting:
    """``why_not(caller, pid)``: None when the node registered as ``caller`` runs as process ``pid`` on this
    host, else why the offer is not believed, in words. Remembers the last ``remember`` believed pairs."""

    def __init__(self, *, master_uri: Callable[[], str] = lambda: str(rosgraph.get_master_uri()),
                 ask: Callable[..., Any] = _ask, remember: int = 256) -> None:
        self._master_uri = master_uri
        self._ask = ask
        self._remember = remember
        self._believed: "collections.OrderedDict[Tuple[str, int], None]" = collections.OrderedDict()
        self._lock = threading.Lock()

    def why_not(self, caller: str, pid: int) -> Optional[str]:
        who = short(caller)
        if pid <= 0:
            return f"the offer of {who} names no process (pid {pid})"
        key = (caller, pid)
        with self._lock:
            if key in self._believed:
                self._believed.move_to_end(key)
                return None
        try:
            uri = str(self._ask(self._master_uri(), "lookupNode", caller))
        except LookupError as exc:
            return f"{who} is not a node registered with the ROS master ({short(str(exc))})"
        except (OSError, xmlrpc.client.Error, ValueError, TypeError) as exc:
            return f"the ROS master did not say where {who} runs ({type(exc).__name__}: {short(str(exc))})"
        try:
            real = int(self._ask(uri, "getPid"))
        except (LookupError, OSError, xmlrpc.client.Error, ValueError, TypeError) as exc:
            return f"node {who} at {short(uri)} did not tell its process id ({type(exc).__name__}: {short(str(exc))})"
        if real != pid:
            return (f"the offer names process {pid}, but node {who} (registered at {short(uri)}) runs as process "
                    f"{real}: not its offer")
        with self._lock:
            self._believed[key] = None
            while len(self._believed) > self._remember:
                self._believed.popitem(last=False)
        return None

    def forget(self, caller: str, pid: int) -> None:
        """A believed subscriber's process is gone: ask again next time."""
        with self._lock:
            self._believed.pop((caller, pid), None)


#: the process's one vetting (the master and nodes answer for the whole process)
vetting = OfferVetting()
