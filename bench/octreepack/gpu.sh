#!/bin/sh
# gpu.sh: the octreepack checks that need a GPU host. Runs the CUDA sampling test (the player's
# CANOPY_HD descent + brick sampling on the device vs the CPU reference) and the pack benchmark.
#   BIN=build/bin OUT=/tmp/octreepack-gpu sh bench/octreepack/gpu.sh
set -eu
: "${BIN:?set BIN to the folder with test_octreepack and bench-octreepack}"
: "${OUT:?set OUT to a folder for the logs}"
mkdir -p "$OUT"
"$BIN/test_octreepack" --gtest_filter='*cuda_*' 2>&1 | tee "$OUT/test_octreepack_cuda.log"
grep -q '\[  PASSED  \] 1 test' "$OUT/test_octreepack_cuda.log" || { echo "gpu.sh: CUDA sampling test did not pass (skipped or failed)" >&2; exit 1; }
"$BIN/bench-octreepack" "$OUT/work" | tee "$OUT/bench_octreepack.md"
