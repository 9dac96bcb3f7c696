"""micros_rt's logging (micros_rt/log.py): the caller never waits for a handler, records keep the
caller's file, line and function, a full queue drops and counts."""

from __future__ import annotations

import logging
import threading
import time
from typing import List

from micros_rt import log as _logging


class _Gate(logging.Handler):
    """A handler that waits at a gate, as rospy's /rosout handler waits for an unreachable master."""

    def __init__(self) -> None:
        super().__init__()
        self.gate = threading.Event()
        self.records: List[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.gate.wait(30)
        self.records.append(record)


def _logger(name: str) -> tuple[_logging.NonBlockingLogger, _Gate]:
    target = logging.getLogger(name)
    target.setLevel(logging.DEBUG)
    target.propagate = False
    gate = _Gate()
    target.handlers = [gate]
    return _logging.nonblocking_logger(name), gate


def test_records_carry_the_callers_file_line_and_function() -> None:
    log, gate = _logger("micros_rt_test.where")
    gate.gate.set()
    line = _where(log)
    _logging.flush(10)
    [record] = gate.records
    assert (record.pathname, record.lineno, record.funcName) == (__file__, line, "_where")
    assert record.getMessage() == "at 42"


def _where(log: _logging.NonBlockingLogger) -> int:
    log.warning("at %d", 42)
    return _where.__code__.co_firstlineno + 1


def test_a_blocked_handler_does_not_block_the_caller_and_a_full_queue_counts_drops() -> None:
    log, gate = _logger("micros_rt_test.blocked")
    before = _logging.dropped
    t0 = time.monotonic()
    n = _logging._queue.maxsize + 50
    for i in range(n):
        log.info("record %d", i)
    elapsed = time.monotonic() - t0
    assert elapsed < 10, elapsed                     # never waited for the handler
    assert _logging.dropped - before >= 49           # the queue holds maxsize; one is at the gate
    gate.gate.set()
    _logging.flush(30)
    assert len(gate.records) + (_logging.dropped - before) == n
    assert [r.getMessage() for r in gate.records[:2]] == ["record 0", "record 1"]


def test_exception_keeps_exc_info_for_the_handlers() -> None:
    log, gate = _logger("micros_rt_test.exc")
    gate.gate.set()
    try:
        raise RuntimeError("boom")
    except RuntimeError:
        log.exception("failed: %s", "x")
    _logging.flush(10)
    [record] = gate.records
    assert record.exc_info is not None and record.exc_info[0] is RuntimeError
    assert "RuntimeError: boom" in logging.Formatter().format(record)
