"""perf_counter instrumentation of micros_rt's hot path, for bench.py children (BENCH_INSTRUMENT=1).

cProfile sees only the main thread, and micros_rt delivers on its own thread; this wraps the
hot-path functions (all threads) and prints per-call mean/median times with the child's RESULT line.
"""

import statistics
import sys
import time
from collections import defaultdict

_T = defaultdict(list)


def _wrap(owner, name, label):
    orig = getattr(owner, name)

    def timed(*a, **k):
        t0 = time.perf_counter()
        try:
            return orig(*a, **k)
        finally:
            _T[label].append(time.perf_counter() - t0)

    setattr(owner, name, timed)


def install():
    import micros_rt._publication as publication
    import micros_rt._subscription as subscription
    import micros_rt.node as node
    import micros_rt.dds.endpoints as ep

    _wrap(node.Publisher, "publish", "Publisher.publish (total)")
    _wrap(publication._Publication, "publish", "_Publication.publish")
    _wrap(ep.DDSWriter, "write", "DDSWriter.write (encode+ddspy_write)")
    _wrap(ep, "ddspy_write", "ddspy_write (C)")
    _wrap(ep, "ddspy_take", "ddspy_take (C)")
    _wrap(ep.DDSReader, "take_raw", "DDSReader.take_raw")
    _wrap(ep.DDSReader, "writer_info", "DDSReader.writer_info")
    _wrap(subscription._Subscription, "_take", "_Subscription._take (whole batch)")
    _wrap(subscription._Subscription, "_deliver_dds", "_Subscription._deliver_dds")
    _wrap(subscription._Subscription, "_deliver", "_Subscription._deliver (incl. callback)")
    _wrap(subscription._Subscription, "_check_deadline", "_Subscription._check_deadline")
    _wrap(subscription._Inbox, "wait", "_Inbox.wait (blocking)")
    import rospy.topics
    _wrap(rospy.topics, "args_kwds_to_message", "args_kwds_to_message")


def report():
    lines = ["INSTRUMENT label: calls, mean us, median us, total ms"]
    for label, v in sorted(_T.items(), key=lambda kv: -sum(kv[1])):
        if v:
            lines.append(f"INSTRUMENT {label:<42} {len(v):>8} {statistics.fmean(v)*1e6:>9.1f} "
                         f"{statistics.median(v)*1e6:>9.1f} {sum(v)*1e3:>9.1f}")
    sys.stdout.write("\n".join(lines) + "\n")
    sys.stdout.flush()


def install_dds():
    """The same for the raw cyclonedds-python children (high-level API)."""
    import cyclonedds.pub as pub
    import cyclonedds.sub as sub
    import cyclonedds.core as core

    _wrap(pub.DataWriter, "write", "DataWriter.write (serialize+ddspy_write)")
    _wrap(pub, "ddspy_write", "ddspy_write (C)")
    _wrap(sub.DataReader, "take", "DataReader.take (+deserialize)")
    _wrap(core.WaitSet, "wait", "WaitSet.wait (blocking)")
