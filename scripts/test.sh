#!/usr/bin/env bash
# Set up .venv (pinned dependencies) and run the whole test suite on CPU.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-venv.sh
exec .venv/bin/python -m pytest "$@"
