#!/usr/bin/env bash
# Create or refresh .venv with the pinned dependencies and wtinspect installed (editable).
# Idempotent: re-installs only when requirements.lock or pyproject.toml changed.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.wtinspect-installed
want=$(cat requirements.lock pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  .venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.lock >&2
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps -e . >&2
  # Compile the planner's numba kernels now (10-20 s once), not in the user's first plan.
  .venv/bin/python -m wtcli.warmup >&2
  echo "$want" > "$stamp"
fi
# Byte-compile the package (as pip does for a regular install): a Python told not to write .pyc
# files (PYTHONDONTWRITEBYTECODE) would otherwise compile it afresh in every command, ~0.1 s of
# a 2 s photo -> plan. Only what changed is compiled again.
.venv/bin/python -m compileall -q wtcli >&2
