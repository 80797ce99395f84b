#!/usr/bin/env bash
# The main job on the shipped sample data with the shipped model. Sets up .venv first.
# Outputs go to ./demo-out/ (or $1); see README "What the demo does".
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-venv.sh
OUT=${1:-demo-out}
mkdir -p "$OUT"
W=.venv/bin/wtinspect
$W --version
# 1. Segment the sample photos with the shipped Mask R-CNN (instances, I_t, overlays).
$W segment sample_images/images --out "$OUT/segment"
# 2-3. Contours and blade angles on the renders' ground-truth masks: the shipped model is still
#      early (models/README.md), so the angles shown come from the true masks.
$W contours sample_images/instances.json --out "$OUT/contours.json"
$W pitch "$OUT/contours.json" --out "$OUT/pitch.json" --overlay-dir "$OUT/overlays"
# 4. Plan the two-turbine sample site: plan JSON, path picture, QGC/MAVLink/GeoJSON exports.
$W plan sample_images/turbines.yaml --out "$OUT/plan.json" --export-dir "$OUT/exports" \
    --picture "$OUT/plan.png"
# 5. Fly it in the simulator with the shipped 'tiny' wind scenario; report + pictures.
$W fly "$OUT/plan.json" --scenario tiny --out "$OUT/flight.json" --pictures "$OUT/flight"
echo "demo outputs in $OUT/" >&2
