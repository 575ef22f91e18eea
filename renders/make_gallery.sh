#!/bin/sh
# The README's gallery: equal-time comparisons (3 s per strategy) with sweeps, against the
# shipped references. Git keeps the charts, grids and tables the README shows (.gitignore).
set -e
cd "$(dirname "$0")/.."
for scene in veach_mis cornell; do
    tracer compare "scenes/$scene.toml" --reference "renders/references/$scene.exr" \
        --time 3 --sweep --out "renders/gallery/$scene"
done
