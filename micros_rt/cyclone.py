"""The first import of ``cyclonedds`` in a process: once, whole, under one lock, whatever thread asks first.

cyclonedds's modules import each other in a cycle (``cyclonedds.idl`` <-> ``cyclonedds.idl._main``,
``cyclonedds.builtin`` <-> ``cyclonedds.builtin_types``, ...). Two threads importing them for the first time at
once, from different entry points, meet a module the other has only half run: Python breaks the lock cycle by
handing one of them the half-initialised module, and the import fails ("cannot import name 'IdlStruct' from
partially initialized module 'cyclonedds.idl'"). A micros_rt node asks from several threads in its first second
(the main thread mapping a service's types, the housekeeping thread starting the host's ROS 2 watcher, a lazy DDS
open for a peer's ``requestTopic``): measured, 6 of 6 starts of a node that offered a service and published in
its first second lost DDS for the whole process.

So every micros_rt code path calls :func:`import_cyclonedds` before its own ``import cyclonedds...`` (a test,
``tests/unit/test_cyclone_import.py``, checks every one), and the whole package is imported here, by one thread,
while the others wait.
"""

from __future__ import annotations

import importlib
import threading
from typing import Optional

from .exceptions import DDSUnavailableError

__all__ = ["import_cyclonedds", "MODULES"]

#: Every cyclonedds module micros_rt uses, imported in this order (the package's own order of dependency)
MODULES = (
    "cyclonedds.internal",
    "cyclonedds._clayer",
    "cyclonedds.core",
    "cyclonedds.qos",
    "cyclonedds.idl",
    "cyclonedds.idl.types",
    "cyclonedds.idl._xt_builder",
    "cyclonedds.domain",
    "cyclonedds.topic",
    "cyclonedds.pub",
    "cyclonedds.sub",
    "cyclonedds.builtin_types",
    "cyclonedds.builtin",
)

_lock = threading.Lock()
_loaded = False
_error: Optional[str] = None


def import_cyclonedds() -> None:
    """Import cyclonedds (once per process; later calls cost an attribute read).

    Raises :class:`~micros_rt.exceptions.DDSUnavailableError`, naming the real cause and what to do, when the
    package cannot be imported; every later call raises the same."""
    global _loaded, _error
    if _loaded:
        return
    with _lock:
        if _loaded:
            return
        if _error is None:
            try:
                for name in MODULES:
                    importlib.import_module(name)
            except Exception as exc:  # ImportError, or the C library failing to load (OSError)
                _error = (f"the cyclonedds Python package cannot be imported ({type(exc).__name__}: {exc}); "
                          "reinstall it in this Python environment (pip install cyclonedds; scripts/setup.sh "
                          "does it), or set MICROS_RT_DISABLE_DDS=1 to run on TCPROS and shared memory only")
            else:
                _loaded = True
                return
        raise DDSUnavailableError(_error)
