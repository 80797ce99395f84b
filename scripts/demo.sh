#!/usr/bin/env bash
# The main job on the shipped sample data, with the shipped model. Sets up .venv first.
# Outputs go to ./demo-out/ (or $1).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-venv.sh
OUT=${1:-demo-out}
mkdir -p "$OUT"
W=.venv/bin/wtinspect
$W --version
# The chain grows with each stage: see README "What the demo does".
$W contours sample_images/instances.json --out "$OUT/contours.json"
$W pitch "$OUT/contours.json" --out "$OUT/pitch.json" --overlay-dir "$OUT/overlays"
echo "demo outputs in $OUT/" >&2
