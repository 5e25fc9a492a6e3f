#!/usr/bin/env bash
# gpu-all.sh: every GPU check and benchmark in one call on the GPU host (the lead's `device` run).
#
# Here:   cmake --build build && ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/* -- ../shared
# There:  bash bench/gpu-all.sh [tool...]     (with .gpu carried; logs -> $OUT/logs.tgz)
#
# Tests were compiled with absolute paths to the checkout they were built in (CANOPY_BUILT_AT,
# default /work/main), its build folder and ../shared; the script recreates those paths on the GPU
# host as links to this copy of the tree and into the unpacked bundle.
set -u
here=$(pwd)
B=/tmp/canopy-bundle
mkdir -p "$B" && tar xJf .gpu/canopy.tar.xz -C "$B"
export PATH=$B/bin:$PATH LD_LIBRARY_PATH=$B/lib BIN=$B/bin
built=${CANOPY_BUILT_AT:-/work/main}
mkdir -p "$(dirname "$built")"
[[ -e $built ]] || ln -s "$here" "$built"
[[ -e $(dirname "$built")/shared ]] || ln -s "$B/share/shared" "$(dirname "$built")/shared"
mkdir -p build && { [[ -e build/bin ]] || ln -s "$B/bin" build/bin; }
W=/tmp/gpu-logs
mkdir -p "$W"
nvidia-smi > "$W/nvidia-smi.txt" 2>&1
date -u > "$W/date.txt"
tools=("$@")
((${#tools[@]})) || tools=(core plant lbsolve haar octreepack play)
for t in "${tools[@]}"; do
  echo "=== $t $(date -u +%T)"
  start=$(date +%s)
  if [[ $t == core ]]; then
    "$BIN/test_core" --gtest_filter='*cuda*' > "$W/core.log" 2>&1
  elif [[ $t == plant ]]; then
    # A real plant's light field: oak_medium voxelised and lit on the GPU (timed), for haar's
    # bit-exact CUDA decode check and benchmark (LIGHT), and the same solve on the CPU to compare.
    {
      "$BIN/canopy-voxelize" /work/shared/assets/plants/oak_medium.glb -o "$W/oak64.density.vdb" --resolution 64 &&
      "$BIN/canopy-voxelize" /work/shared/assets/plants/oak_medium.glb -o "$W/oak128.density.vdb" --resolution 128 &&
      "$BIN/canopy-lbsolve" "$W/oak128.density.vdb" -o "$W/oak128.light.vdb" --device cuda --json > "$W/oak128.lbsolve.cuda.json" &&
      "$BIN/canopy-lbsolve" "$W/oak64.density.vdb" -o "$W/oak64.light.vdb" --device cuda --json > "$W/oak64.lbsolve.cuda.json" &&
      "$BIN/canopy-lbsolve" "$W/oak64.density.vdb" -o "$W/oak64.cpu.light.vdb" --device cpu --json > "$W/oak64.lbsolve.cpu.json" &&
      python3 - "$W" <<'PY'
import json, sys
w = sys.argv[1]
for name in ("oak128.lbsolve.cuda", "oak64.lbsolve.cuda", "oak64.lbsolve.cpu"):
    r = json.load(open(f"{w}/{name}.json"))
    keys = {k: r[k] for k in r if k in ("seconds", "wall_seconds", "node_updates", "node_updates_per_second", "device")}
    print(name, json.dumps(keys))
PY
    } > "$W/plant.log" 2>&1
    export LIGHT=$W/oak64.light.vdb
  else
    OUT=$W/$t timeout "${GPU_STEP_TIMEOUT:-240}" bash "bench/$t/gpu.sh" > "$W/$t.log" 2>&1
  fi
  rc=$?
  echo "rc=$rc seconds=$(( $(date +%s) - start ))" | tee -a "$W/$t.log"
  grep -E "PASSED|FAILED|SKIPPED|Failure|rc=|error" "$W/$t.log" | tail -12
done
tar czf "$OUT/logs.tgz" -C "$W" .
