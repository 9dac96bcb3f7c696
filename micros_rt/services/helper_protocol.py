"""The frames between a micros_rt process (:mod:`micros_rt.services.gateway`) and the host's ROS 2 helper
(:mod:`micros_rt.services.ros2_helper`): one table of op codes both sides import. It imports nothing but the
standard library, so the helper's interpreter (rclpy's, without micros_rt or rospy) imports it from the helper's
own directory.

A frame: ``<I`` length of the rest, ``<BIH`` op, call id, meta length (:data:`HEAD`), then the meta (UTF-8 JSON)
and a binary body (a serialized ROS 2 message, CDR with its encapsulation header).

>>> HEAD.size, len(set(OPS.values())) == len(OPS)
(11, True)
"""

from __future__ import annotations

import json
import struct
from typing import Any, Dict, Optional, Tuple

# micros_rt -> helper: services (a ROS 1 server offered to ROS 2, a ROS 2 server reached, calls both ways)
ADVERTISE, UNADVERTISE, CLIENT, READY, CALL, CANCEL, RESPONSE, FAIL = 1, 2, 3, 4, 5, 6, 7, 8
# micros_rt -> helper: actions (micros_rt.actions): serve a ROS 1 action to ROS 2 (A_SERVE .. A_DONE), reach a
# ROS 2 action server (A_CLIENT .. A_FORGET)
A_SERVE, A_UNSERVE, A_VERDICT, A_FEEDBACK, A_DONE, A_CLIENT, A_SEND, A_CANCEL, A_READY, A_FORGET = range(9, 19)
#: the names of the services ROS 2 servers offer now (DDS discovery), whatever their type
SERVICE_NAMES = 19
# helper -> micros_rt
STATUS, RESULT, ERROR, REQUEST, HELLO = 20, 21, 22, 23, 24
# helper -> micros_rt, each with {"name": action}: a ROS 2 client's goal and cancel; a ROS 2 server's answers
G_GOAL, G_CANCEL, G_ACCEPTED, G_FEEDBACK, G_RESULT = range(25, 30)
#: helper -> micros_rt: words for the process's log ({"text": ...}): a response lost, a frame dropped
LOG = 30
# HELLO goes both ways: a process's first frame names its node ({"node": ...}); the helper answers with its pid
# and RMW ({"pid": ..., "rmw": ...})

#: a frame's head after its length: op, call id, meta length
HEAD = struct.Struct("<IBIH")

#: every op code by name (a frame with another op is the other side's bug, said in words)
OPS: Dict[str, int] = {name: value for name, value in globals().items()
                       if name.isupper() and isinstance(value, int) and not isinstance(value, bool)}


def encode(op: int, cid: int, meta: Optional[Dict[str, Any]] = None, body: bytes = b"") -> bytes:
    """One frame.

    >>> read_frame(__import__("io").BytesIO(encode(HELLO, 0, {"node": "n"}, b"x")))
    (24, 0, {'node': 'n'}, b'x')
    """
    raw = json.dumps(meta).encode() if meta else b""
    return HEAD.pack(HEAD.size - 4 + len(raw) + len(body), op, cid, len(raw)) + raw + body


def read_frame(reader: Any) -> Optional[Tuple[int, int, Dict[str, Any], bytes]]:
    """The next frame (op, call id, meta, body) from a connection's buffered reader; None at its end."""
    head = reader.read(HEAD.size)
    if len(head) < HEAD.size:
        return None
    length, op, cid, meta_len = HEAD.unpack(head)
    rest = reader.read(length - (HEAD.size - 4))
    if len(rest) < length - (HEAD.size - 4):
        return None
    return op, cid, (json.loads(rest[:meta_len]) if meta_len else {}), bytes(rest[meta_len:])
