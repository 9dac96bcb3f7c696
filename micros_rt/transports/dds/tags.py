"""micros_rt's USER_DATA tag on its DDS endpoints (``micros_rt;graph=...;node=...;``): made by the endpoints,
read by discovery. A module of its own that imports no DDS library, so that a node that only takes part in
watching the domain (:mod:`.watch`, every node but the host's watcher) never loads cyclonedds."""

from __future__ import annotations

from typing import Dict, Optional

__all__ = ["USER_DATA_PREFIX", "make_user_data", "parse_user_data"]

USER_DATA_PREFIX = b"micros_rt;"


def make_user_data(**fields: str) -> bytes:
    """USER_DATA tag of micros_rt endpoints: ``micros_rt;graph=...;node=...;``.

    >>> make_user_data(node="/talker")
    b'micros_rt;node=/talker;'
    """
    return USER_DATA_PREFIX + b"".join(f"{k}={v};".encode() for k, v in fields.items())


def parse_user_data(data: Optional[bytes]) -> Optional[Dict[str, str]]:
    """The fields of a micros_rt tag, or None for an endpoint micros_rt did not create.

    >>> parse_user_data(b"micros_rt;node=/talker;"), parse_user_data(b"typehash=RIHS01_00;")
    ({'node': '/talker'}, None)
    """
    if not data or not data.startswith(USER_DATA_PREFIX):
        return None
    out: Dict[str, str] = {}
    for part in data[len(USER_DATA_PREFIX):].decode("utf-8", "replace").split(";"):
        if "=" in part:
            k, _, v = part.partition("=")
            out[k] = v
    return out
