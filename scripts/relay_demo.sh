#!/bin/bash
# Set up, then run the two-robot relay demo: scripts/relay_demo.sh [args for examples/relay_demo.py, e.g. --seconds 5]
# As root: the demo makes two network namespaces (the robots), a veth link between them and a tc qdisc.
set -euo pipefail

if [ "$(id -u)" -ne 0 ]; then
    echo "relay_demo.sh: run it as root (sudo ./scripts/relay_demo.sh): the demo makes network namespaces" \
         "and a tc qdisc, and setup.sh installs Debian packages" >&2
    exit 2
fi

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO_ROOT"

scripts/setup.sh
exec .venv/bin/python examples/relay_demo.py "$@"
