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
((${#tools[@]})) || tools=(core lbsolve haar octreepack play)
for t in "${tools[@]}"; do
  echo "=== $t $(date -u +%T)"
  start=$(date +%s)
  if [[ $t == core ]]; then
    "$BIN/test_core" --gtest_filter='*cuda*' > "$W/core.log" 2>&1
  else
    OUT=$W/$t timeout "${GPU_STEP_TIMEOUT:-240}" bash "bench/$t/gpu.sh" > "$W/$t.log" 2>&1
  fi
  rc=$?
  echo "rc=$rc seconds=$(( $(date +%s) - start ))" | tee -a "$W/$t.log"
  grep -E "PASSED|FAILED|SKIPPED|Failure|rc=|error" "$W/$t.log" | tail -12
done
tar czf "$OUT/logs.tgz" -C "$W" .
