#!/bin/bash
# Set up, type-check (mypy strict, config in pyproject.toml) and run the test suite.
# pytest runs even when mypy fails; the script exits non-zero if either failed.
#   scripts/test.sh            everything (CI, README): ~24 min on 2 cores, the 25 slowest tests listed at the end
#   scripts/test.sh --fast     the edit loop's tier: unit, contract and doctests, and one integration test per
#                              transport and per program (tests/conftest.py SMOKE): < 3 min on 2 cores
# Extra arguments go to pytest, e.g.  scripts/test.sh -k harness -x
set -euo pipefail

tier=(--durations=25)
if [[ "${1:-}" == "--fast" ]]; then
    shift
    tier=(-m "not integration or smoke" --durations=10)
fi

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO_ROOT"

scripts/setup.sh

echo "== mypy"
mypy_rc=0
.venv/bin/mypy || mypy_rc=$?

ETH0_TX=/sys/class/net/eth0/statistics/tx_packets
tx_before=""
if [[ -r "$ETH0_TX" ]]; then
    tx_before="$(cat "$ETH0_TX")"
    echo "== eth0 tx_packets before pytest: $tx_before"
fi

echo "== pytest"
rc=0
.venv/bin/python -m pytest -q tests "${tier[@]}" "$@" || rc=$?

if [[ -n "$tx_before" ]]; then
    tx_after="$(cat "$ETH0_TX")"
    echo "== eth0 tx_packets after pytest: $tx_after (+$((tx_after - tx_before)))"
fi
if ((mypy_rc != 0)); then
    echo "== FAILED: mypy (exit $mypy_rc)" >&2
    exit "$mypy_rc"
fi
exit "$rc"
