#!/usr/bin/env bash
# Worked example of `shm-ros explain` (docs/explain.md): a two-day girder campaign whose deck
# stiffens below a knee temperature (a hidden effect the nominal structure file knows nothing of);
# explain reads the simulator's tracked-modes table of the campaign's true modes.
#
#     examples/explain_example.sh [OUT] [WINDOWS]   (default OUT: ./explain_example, WINDOWS: 288)
#
# 288 bursts of 60 s, one every 10 minutes (two days of the daily temperature cycle); fewer windows
# make a shorter campaign (the tests run it with 96).
set -euo pipefail
OUT="${1:-explain_example}"
WINDOWS="${2:-288}"
shm-ros simulate girder --windows "$WINDOWS" --window-s 60 --pause-s 540 --seed 11 --quiet \
    --effects "temperature_bilinear:where=deck:knee_c=2.0:below_per_c=-0.04" --out "$OUT"
shm-ros explain --structure "$OUT/structure.yaml" --modes "$OUT/truth_modes.csv" --out "$OUT/explain"
python "$(dirname "$0")/explain_example_figures.py" "$OUT"  # the figures of docs/explain.md (project venv)
