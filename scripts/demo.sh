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
# 2-3. Contours and blade angles on what the model found (not the renders' true masks).
$W contours "$OUT/segment/instances.json" --out "$OUT/contours.json"
$W pitch "$OUT/contours.json" --out "$OUT/pitch.json" --overlay-dir "$OUT/overlays"
# 4. Plan the two-turbine sample site, T1's blade angles from its photo (segment -> contours ->
#    pitch -> back-projection, as `plan` does for any photo), T2's from the YAML: plan JSON,
#    path picture, QGC/MAVLink/GeoJSON exports.
$W plan sample_images/turbines.yaml T1=sample_images/images/00000.jpg --out "$OUT/plan.json" \
    --export-dir "$OUT/exports" --picture "$OUT/plan.png"
# 5. Fly it in the simulator with the shipped 'tiny' wind scenario; report + pictures.
$W fly "$OUT/plan.json" --scenario tiny --out "$OUT/flight.json" --pictures "$OUT/flight"
echo "demo outputs in $OUT/" >&2
