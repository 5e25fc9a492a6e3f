#!/bin/sh
# End to end on the real oak at 64^3, CPU: canopy-voxelize -> canopy-lbsolve -> canopy-lbsolve info.
# Usage: oak_e2e.sh VOXELIZE LBSOLVE ASSET WORKDIR
# The solve runs a fixed 12 iterations (--tolerance 0) to keep CI time bounded on 2 cores (57 solves
# of 64^3); convergence itself is tested on small lattices in test_collide.
set -eu
voxelize=$1 lbsolve=$2 asset=$3 work=$4
rm -rf "$work"
mkdir -p "$work"
"$voxelize" "$asset" -o "$work/oak.density.vdb" --resolution 64 -q
"$lbsolve" "$work/oak.density.vdb" -o "$work/oak.light.vdb" --device cpu --iterations 12 --tolerance 0 -q --json > "$work/report.json"
"$lbsolve" info "$work/oak.light.vdb" --json > "$work/info.json"
grep -q '"kind": "bases"' "$work/info.json"
grep -q '"B18"' "$work/info.json"
grep -q '"exit_code": 0' "$work/report.json"
# Light was stored somewhere and is not all zero: B00 (ambient) must be positive at stored nodes.
grep -q '"active_voxels": [1-9]' "$work/info.json"
echo "oak_e2e: ok"
