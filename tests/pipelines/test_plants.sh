#!/usr/bin/env bash
# `make plants` over a directory of meshes on the CPU at a small resolution; every packed file
# verifies.   usage: test_plants.sh BIN SOURCE_DIR PLANTS_DIR
set -euo pipefail
BIN=$1 SRC=$2 PLANTS=$3
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
make --no-print-directory -C "$SRC/pipelines" -j2 BIN="$BIN" O="$T" PLANTS="$PLANTS" RESOLUTION=24 DEVICE=cpu plants
n=0
for mesh in "$PLANTS"/*.glb "$PLANTS"/*.gltf "$PLANTS"/*.obj "$PLANTS"/*.ply; do
  [[ -e $mesh ]] || continue
  name=$(basename "${mesh%.*}")
  "$BIN/canopy-octreepack" verify "$T/plants/$name.canopy"
  n=$((n + 1))
done
((n > 0)) || { echo "FAIL: no meshes in $PLANTS"; exit 1; }
echo "PASS: $n plants packed and verified"
# The same with detail lattices (DETAIL: geometry 4x finer than the light lattice, format 2.0).
make --no-print-directory -C "$SRC/pipelines" -j2 BIN="$BIN" O="$T/detail" PLANTS="$PLANTS" RESOLUTION=24 DETAIL=96 DEVICE=cpu plants
m=0
for mesh in "$PLANTS"/*.glb "$PLANTS"/*.gltf "$PLANTS"/*.obj "$PLANTS"/*.ply; do
  [[ -e $mesh ]] || continue
  name=$(basename "${mesh%.*}")
  f="$T/detail/plants/$name.canopy"
  "$BIN/canopy-octreepack" verify "$f"
  "$BIN/canopy-octreepack" info "$f" | grep -q "density lattice 96x96x96, light lattice 24x24x24 (detail x4" ||
    { echo "FAIL: $f is not a detail pack"; "$BIN/canopy-octreepack" info "$f"; exit 1; }
  m=$((m + 1))
done
((m == n)) || { echo "FAIL: $m of $n detail packs"; exit 1; }
echo "PASS: $m plants packed with detail lattices and verified"
