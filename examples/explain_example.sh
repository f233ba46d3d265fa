#!/usr/bin/env bash
# Worked example of `shm-ros explain` (docs/explain.md): a two-day girder campaign whose deck
# stiffens below a knee temperature (a hidden effect the nominal structure file knows nothing of),
# simulated as a recording, then identified, tracked and explained from the bag.
#
#     examples/explain_example.sh [OUT]        (default OUT: ./explain_example)
#
# 288 bursts of 120 s, one every 10 minutes (two days of the daily temperature cycle).
set -euo pipefail
OUT="${1:-explain_example}"
shm-ros simulate girder --windows 288 --window-s 120 --pause-s 480 --seed 11 --quiet \
    --effects "temperature_bilinear:where=deck:knee_c=2.0:below_per_c=-0.04" --out "$OUT"
shm-ros explain --structure "$OUT/structure.yaml" --bag "$OUT/bag" --window 120 --out "$OUT/explain"
