#!/usr/bin/env bash
# Regenerates the committed figures in reference_py/figures/ (`make figures`; README: "A phantom
# insertion: Model II against Model III").  Every number the README quotes beside a figure is
# printed here by the tools.  NTE_REF overrides the command (default: .venv/bin/nte-ref).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
nte=${NTE_REF:-$root/.venv/bin/nte-ref}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# phantom_m2_m3.png: one skin-on-muscle phantom record (seed 7: 2 mm/s in to 25 mm of stage,
# a 5.26 s dwell, back out; two membrane ruptures), each model with its defaults
"$nte" phantom skin-on-muscle --seed 7 --out "$work/rec.csv"
"$nte" estimate "$work/rec.csv" --model 2 --out "$work/m2.csv"
"$nte" estimate "$work/rec.csv" --model 3 --out "$work/m3.csv"
"$nte" plot "$work/m2.csv" "$work/m3.csv" --label "Model II" --label "Model III" \
  --input "$work/rec.csv" --truth "$work/rec.truth.json" \
  --title "phantom skin-on-muscle, seed 7: Model II and Model III" \
  --out "$here/phantom_m2_m3.png"
