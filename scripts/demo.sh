#!/bin/bash
# Set up, then run the demo: scripts/demo.sh [args for examples/demo.py]
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO_ROOT"

scripts/setup.sh
exec .venv/bin/python examples/demo.py "$@"
