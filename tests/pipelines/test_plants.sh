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
