"""Unit tests of micros_rt.qos.enforcement (time filter, deadline, lifespan, clock skew) and _stats.LatencyStats."""

from __future__ import annotations

import math
from typing import List, Optional

import pytest

from micros_rt.core.stats import LatencyStats
from micros_rt.qos.enforcement import (
    CLOCK_SKEW_WARN_SECONDS,
    ClockSkewCheck,
    DeadlineMonitor,
    TimeFilter,
    is_expired,
)

S = 1_000_000_000  # ns per second


# ---------------------------------------------------------------------------------------------- TimeFilter


def test_time_filter_zero_admits_everything() -> None:
    f = TimeFilter(0.0)
    assert all(f.admit(t) for t in (0.0, 0.0, 1e-9, 5.0, 4.0))


def test_time_filter_negative_period_admits_everything() -> None:
    f = TimeFilter(-1.0)
    assert all(f.admit(float(t)) for t in range(5))


def test_time_filter_one_per_period() -> None:
    f = TimeFilter(1.0)
    got = [f.admit(t) for t in (0.0, 0.1, 0.999, 1.0, 1.5, 1.999, 2.0, 10.0, 10.5)]
    assert got == [True, False, False, True, False, False, True, True, False]


def test_time_filter_first_message_always_admitted_at_any_time() -> None:
    for start in (-1e9, 0.0, 12345.678):
        assert TimeFilter(5.0).admit(start)


def test_time_filter_rejected_messages_do_not_restart_the_period() -> None:
    f = TimeFilter(1.0)
    assert f.admit(0.0)
    for i in range(1, 10):
        assert not f.admit(i * 0.1)
    assert f.admit(1.0)


def test_time_filter_counts_over_a_stream() -> None:
    f = TimeFilter(0.1)
    admitted = sum(f.admit(i * 0.001) for i in range(1000))  # 1 kHz for 1 s
    assert admitted == 10


# ----------------------------------------------------------------------------------------- DeadlineMonitor


def test_deadline_poll_delivered_sequence() -> None:
    d = DeadlineMonitor(0.5, start=0.0)
    assert d.enabled
    assert d.poll(0.4) is None
    assert d.poll(0.6) == pytest.approx(0.6)
    assert d.missed_total == 1
    assert d.poll(0.7) is None            # reported once per deadline of silence
    assert d.poll(1.09) is None
    assert d.poll(1.1) == pytest.approx(1.1)
    assert d.missed_total == 2
    assert d.delivered(2.0) == pytest.approx(2.0)   # data resumed after 2.0 s of silence
    assert d.delivered(2.1) is None       # no miss since the last delivery
    assert d.missed_total == 2


def test_deadline_no_miss_while_data_flows() -> None:
    d = DeadlineMonitor(0.5, start=0.0)
    t = 0.0
    for _ in range(100):
        t += 0.4
        assert d.poll(t) is None
        assert d.delivered(t) is None
    assert d.missed_total == 0


def test_deadline_delivery_restarts_the_clock() -> None:
    d = DeadlineMonitor(1.0, start=0.0)
    assert d.delivered(0.9) is None
    assert d.poll(1.5) is None            # only 0.6 s since the delivery
    assert d.poll(2.0) == pytest.approx(1.1)
    assert d.missed_total == 1


def test_deadline_resumed_silence_then_new_silence() -> None:
    d = DeadlineMonitor(1.0, start=10.0)
    assert d.poll(11.0) == pytest.approx(1.0)
    assert d.delivered(11.5) == pytest.approx(1.5)
    assert d.poll(12.0) is None
    assert d.poll(12.5) == pytest.approx(1.0)
    assert d.poll(13.5) == pytest.approx(2.0)
    assert d.missed_total == 3
    assert d.delivered(14.0) == pytest.approx(2.5)
    assert d.delivered(14.1) is None


def test_deadline_polls_counted_once_per_deadline_over_long_silence() -> None:
    d = DeadlineMonitor(0.1, start=0.0)
    reports: List[float] = []
    for i in range(1, 1001):              # polled every 10 ms for 10 s
        silent = d.poll(i * 0.01)
        if silent is not None:
            reports.append(silent)
    assert 85 <= d.missed_total <= 100 and len(reports) == d.missed_total
    assert reports == sorted(reports)


def test_deadline_infinite_never_reports() -> None:
    d = DeadlineMonitor(math.inf, start=0.0)
    assert not d.enabled
    assert d.poll(1e12) is None
    assert d.missed_total == 0
    assert d.delivered(1e12) is None


# --------------------------------------------------------------------------------------------- is_expired


def test_is_expired() -> None:
    assert not is_expired(0, 1 * S, 1.0)                     # exactly the valid period: still valid
    assert is_expired(0, 1 * S + 1, 1.0)
    assert is_expired(0, 2 * S, 1.0)
    assert not is_expired(0, 10 ** 18, math.inf)
    assert not is_expired(5 * S, 5 * S + 99_000_000, 0.1)
    assert is_expired(5 * S, 5 * S + 101_000_000, 0.1)
    assert not is_expired(10 * S, 9 * S, 0.001)              # stamped in the future: not expired


# ------------------------------------------------------------------------------------------ ClockSkewCheck


def test_clock_skew_ahead_reported_at_once() -> None:
    c = ClockSkewCheck(limit=1.0, samples=10)
    assert c.observe(-2 * S, 0.0) == pytest.approx(-2.0)
    assert c.done
    assert c.observe(-5 * S, 0.1) is None   # once only


def test_clock_skew_ahead_within_limit_not_reported() -> None:
    c = ClockSkewCheck(limit=1.0, samples=3)
    assert c.observe(-S // 2, 0.0) is None
    assert not c.done


def test_clock_skew_behind_after_n_samples_and_the_window_using_the_smallest_age() -> None:
    c = ClockSkewCheck(limit=1.0, samples=5, window=1.0)
    ages = [5 * S, 3 * S, 2 * S, 9 * S]
    for i, age in enumerate(ages):
        assert c.observe(age, 0.1 * i) is None
        assert not c.done
    assert c.observe(4 * S, 0.5) is None     # five samples, but only 0.5 s of arrivals
    assert not c.done
    assert c.observe(6 * S, 1.0) == pytest.approx(2.0)
    assert c.done
    assert c.observe(100 * S, 1.1) is None


def test_clock_skew_a_backlog_that_drains_within_the_window_is_not_a_clock() -> None:
    # a node starved of CPU while a graph starts takes 20 s of samples at once, oldest first: ten samples
    # stamped 20 s in the past; once the backlog is gone, they arrive in milliseconds
    c = ClockSkewCheck(limit=1.0, samples=10, window=1.5)
    for i in range(200):
        assert c.observe((20 * S) - i * 100_000_000, 30.0 + i * 0.001) is None   # 0.2 s to drain
    for k in range(1, 20):
        assert c.observe(5_000_000, 30.2 + k * 0.1) is None
    assert c.done


def test_clock_skew_one_fast_sample_clears_a_slow_writer() -> None:
    c = ClockSkewCheck(limit=1.0, samples=4, window=0.0)
    for i, age in enumerate((5 * S, 5 * S, S // 100)):
        assert c.observe(age, i * 0.1) is None
    assert c.observe(5 * S, 0.3) is None      # smallest age 10 ms: queueing, not skew
    assert c.done


def test_clock_skew_in_sync_is_done_without_report() -> None:
    c = ClockSkewCheck()
    assert c.limit == CLOCK_SKEW_WARN_SECONDS
    n = c.samples + int(c.window * 10) + 1   # 10 Hz for longer than the window
    results: List[Optional[float]] = [c.observe(1_000_000, i * 0.1) for i in range(n)]
    assert results == [None] * n
    assert c.done
    assert c.observe(50 * S, n * 0.1) is None     # judged: nothing later is reported


def test_clock_skew_ahead_after_some_samples() -> None:
    c = ClockSkewCheck(limit=1.0, samples=10)
    assert c.observe(5 * S, 0.0) is None
    assert c.observe(-3 * S, 0.1) == pytest.approx(-3.0)
    assert c.done


# -------------------------------------------------------------------------------------------- LatencyStats


def test_latency_stats_empty() -> None:
    s = LatencyStats()
    assert math.isnan(s.mean) and math.isnan(s.p50) and math.isnan(s.p99) and math.isnan(s.percentile(0))
    summary = s.summary()
    assert summary["count"] == 0 and math.isnan(summary["max"]) and math.isnan(summary["p99"])


def test_latency_stats_percentiles_nearest_rank() -> None:
    s = LatencyStats()
    for i in range(1, 101):
        s.add(i / 1000.0)
    assert s.count == 100
    assert s.p50 == pytest.approx(0.050)
    assert s.p99 == pytest.approx(0.099)
    assert s.percentile(100) == pytest.approx(0.100)
    assert s.percentile(0) == pytest.approx(0.001)
    assert s.percentile(1) == pytest.approx(0.001)
    assert s.mean == pytest.approx(0.0505)
    assert s.max == pytest.approx(0.100)


def test_latency_stats_order_independent() -> None:
    a, b = LatencyStats(), LatencyStats()
    values = [0.3, 0.1, 0.2, 0.5, 0.4]
    for v in values:
        a.add(v)
    for v in reversed(values):
        b.add(v)
    sa, sb = a.summary(), b.summary()
    assert sa.pop("mean") == pytest.approx(sb.pop("mean"))
    assert sa == sb
    assert a.p50 == 0.3


def test_latency_stats_single_sample() -> None:
    s = LatencyStats()
    s.add(0.007)
    assert s.p50 == s.p99 == s.max == s.mean == 0.007


def test_latency_stats_keep_bounds_percentiles_not_totals() -> None:
    s = LatencyStats(keep=10)
    for _ in range(90):
        s.add(1.0)
    for _ in range(10):
        s.add(0.001)
    assert len(s.samples) == 10
    assert s.p99 == 0.001 and s.p50 == 0.001       # percentiles: the last 10
    assert s.count == 100 and s.max == 1.0         # totals: every message
    assert s.mean == pytest.approx((90 + 0.01) / 100)


def test_latency_stats_budget() -> None:
    s = LatencyStats()
    assert s.add(0.010, budget=0.0) is False       # no budget: never a miss, not checked
    assert s.add(0.010, budget=0.005) is True
    assert s.add(0.005, budget=0.005) is False     # exactly on budget is on time
    assert s.add(0.001, budget=0.005) is False
    assert s.budget_checked == 3 and s.budget_misses == 1
    summary = s.summary()
    assert summary["budget_checked"] == 3 and summary["budget_misses"] == 1
    assert summary["count"] == 4
    assert set(summary) == {"count", "mean", "p50", "p99", "max", "budget_checked", "budget_misses"}


def test_latency_stats_max_of_negative_latencies() -> None:
    """A writer whose clock is ahead gives negative latencies; ``max`` must still be the largest sample."""
    s = LatencyStats()
    s.add(-0.5)
    s.add(-0.2)
    assert s.max == pytest.approx(-0.2)
    assert s.summary()["max"] == pytest.approx(-0.2)
