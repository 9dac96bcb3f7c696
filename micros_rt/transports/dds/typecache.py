"""Cyclone's XTypes type information for micros_rt's types, cached on disk per message type.

Creating a Topic makes cyclonedds-python build the XTypes TypeInformation and TypeMapping of its type
in Python: 25-60 ms per message type measured here (cProfile: ``XTBuilder.process_type``), more than
any other step of a node's start after the imports, and the same bytes every time for a given type.
They are kept under ``~/.cache/micros_rt/xtypes`` (``$XDG_CACHE_HOME`` is honoured), like ``.pyc``
files: the first start of a type builds them, later starts read two small files' worth of bytes.

The key covers everything the bytes depend on: the DDS type name, the ROS message definition (md5 and
full text), micros_rt's field mapping of it and the cyclonedds version. A file that does not read back
exactly (size, checksum) is ignored and rebuilt. ``MICROS_RT_TYPE_CACHE=0`` turns the cache off; a
path names the directory to use (:data:`micros_rt.settings.TYPE_CACHE`).
"""

from __future__ import annotations

import hashlib
import os
import struct
import tempfile
import threading
from pathlib import Path
from typing import Any, Mapping, Optional, Tuple

from ... import settings
from ...cyclone import import_cyclonedds
from ...log import nonblocking_logger

__all__ = ["cache_dir", "load_type_data", "save_type_data", "type_key"]

_log = nonblocking_logger("rosout.micros_rt.dds")

_MAGIC = b"micros_rt xtypes 1\n"
_lock = threading.Lock()


def cache_dir(env: Mapping[str, str] = os.environ) -> Optional[Path]:
    """Where type data is cached; None when ``MICROS_RT_TYPE_CACHE`` is 0/off/false."""
    given = settings.TYPE_CACHE.get(env)
    if given is False:
        return None
    if isinstance(given, Path):
        return given
    base = env.get("XDG_CACHE_HOME") or str(Path(env.get("HOME") or Path.home()) / ".cache")
    return Path(base) / "micros_rt" / "xtypes"


def type_key(idl_class: Any, source: str) -> str:
    """The cache key of ``idl_class`` built from ``source`` (micros_rt's description of the ROS type)."""
    try:
        from importlib.metadata import version

        cyclone = version("cyclonedds")
    except Exception:  # an unusual install: never reuse bytes across unknown versions
        return ""
    text = "\n".join((_MAGIC.decode(), cyclone, str(idl_class.__idl_typename__), source))
    return hashlib.sha256(text.encode()).hexdigest()


class _Deferred:
    """Stands in for the TypeInformation/TypeMapping objects of a type whose bytes came from the cache:
    nobody in micros_rt's path reads them, but if anything does (another type nesting this one and
    being built), they are built then, as cyclonedds would have."""

    __slots__ = ("_idl", "_index")

    def __init__(self, idl: Any, index: int) -> None:
        self._idl = idl
        self._index = index

    def __getattr__(self, name: str) -> Any:
        import_cyclonedds()
        from cyclonedds.idl._xt_builder import XTBuilder

        idl = self._idl
        with _lock:
            if isinstance(idl._xt_data[0], _Deferred):
                idl._xt_data = XTBuilder.process_type(idl.datatype)
        return getattr(idl._xt_data[self._index], name)


def _path(idl_class: Any) -> Optional[Path]:
    key = getattr(idl_class, "__micros_rt_xtypes_key__", "")
    directory = cache_dir()
    if not key or directory is None:
        return None
    return directory / f"{key}.bin"


def _pack(info: bytes, mapping: bytes) -> bytes:
    body = struct.pack("<II", len(info), len(mapping)) + info + mapping
    return _MAGIC + hashlib.sha256(body).digest() + body


def _unpack(blob: bytes) -> Optional[Tuple[bytes, bytes]]:
    if not blob.startswith(_MAGIC):
        return None
    digest, body = blob[len(_MAGIC):len(_MAGIC) + 32], blob[len(_MAGIC) + 32:]
    if len(body) < 8 or hashlib.sha256(body).digest() != digest:
        return None
    n_info, n_map = struct.unpack_from("<II", body)
    if 8 + n_info + n_map != len(body):
        return None
    return body[8:8 + n_info], body[8 + n_info:]


def load_type_data(idl_class: Any) -> bool:
    """Give ``idl_class`` its cached type data (True), or leave it to be built (False)."""
    path = _path(idl_class)
    if path is None:
        return False
    idl = idl_class.__idl__
    if idl._xt_data[0] is not None:
        return True  # built or loaded already in this process
    try:
        data = _unpack(path.read_bytes())
    except OSError:
        return False
    if data is None:
        _log.debug("micros_rt: ignoring a damaged type cache file %s", path)
        return False
    with _lock:
        if idl._xt_data[0] is None:
            idl._xt_bytedata = data
            idl._xt_data = (_Deferred(idl, 0), _Deferred(idl, 1))
    return True


def forget_type_data(idl_class: Any) -> None:
    """Drop cached type data (in memory and on disk) that Cyclone refused."""
    idl = idl_class.__idl__
    with _lock:
        if isinstance(idl._xt_data[0], _Deferred):
            idl._xt_data = (None, None)
            idl._xt_bytedata = (None, None)
    path = _path(idl_class)
    if path is not None:
        try:
            path.unlink()
        except OSError:
            pass


def save_type_data(idl_class: Any) -> None:
    """Store the type data cyclonedds built for ``idl_class`` (atomically; failures only logged)."""
    path = _path(idl_class)
    if path is None:
        return
    info, mapping = idl_class.__idl__._xt_bytedata
    if not isinstance(info, bytes) or not isinstance(mapping, bytes):
        return
    try:
        if path.exists():  # raises PermissionError where the cache's directory cannot be entered
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(_pack(info, mapping))
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
    except OSError as exc:
        _log.debug("micros_rt: cannot cache DDS type data in %s (%s)", path.parent, exc)
