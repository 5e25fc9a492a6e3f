#!/usr/bin/env bash
# gpu-pull-sun.sh: the GPU checks and measurements of 2026-12-01's second session, in one device call:
# the dense "pull" lbsolve scheme (pull_stream.h) and the scattered-only sun bases (beam.h; the
# player's shading now scales them by the sun radiance).
#
# Here (from the repo root, after a Release build with -DCMAKE_CUDA_ARCHITECTURES=90):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{canopy-*,test_core,test_haar_cuda,\
#      test_lbsolve_cuda,test_octreepack,test_play_cuda,bench_lbsolve,bench_lbsolve_streams} -- ../shared
# There:  bash bench/gpu-pull-sun.sh       (.gpu carried; logs and tables under $OUT)
#   1. CUDA tests: test_play_cuda (GPU frames vs CPU, lit forests with and without the direct sun),
#      test_octreepack's device sampling, test_core, test_haar_cuda.
#   2. bench/lbsolve/gpu.sh: test_lbsolve_cuda (every scheme, pull included, bit for bit against the
#      CPU), bench_lbsolve_streams, bench_lbsolve (shift, shift-split, push, pull; plant and full box
#      at 128^3 and 256^3; 57 solves), canopy-lbsolve on oak_medium at 128^3 with each scheme.
set -u
here=$(pwd)
B=/tmp/canopy-bundle
mkdir -p "$B" && tar xJf .gpu/canopy.tar.xz -C "$B"
export PATH=$B/bin:$PATH LD_LIBRARY_PATH=$B/lib BIN=$B/bin
built=${CANOPY_BUILT_AT:-/work/main}  # tests carry absolute paths of the checkout they were built in
mkdir -p "$(dirname "$built")"
[[ -e $built ]] || ln -s "$here" "$built"
[[ -e $(dirname "$built")/shared ]] || ln -s "$B/share/shared" "$(dirname "$built")/shared"
mkdir -p build && { [[ -e build/bin ]] || ln -s "$B/bin" build/bin; }
O=${OUT:-/tmp/out}
mkdir -p "$O"
status=0
nvidia-smi -L | tee "$O/device.txt"; date -u | tee -a "$O/device.txt"
step() { echo "=== $1 $(date -u +%T)"; }
gtest() {  # gtest NAME BINARY [args]: verdicts on stdout, the log under $O; a failure or skip fails the run
  local log=$O/$1.log; shift
  timeout 240 "$@" > "$log" 2>&1 || status=1
  grep -E "^\[ +(OK|FAILED|PASSED|SKIPPED) +\]|RMS" "$log"
  ! grep -q "SKIPPED" "$log" || status=1
}
step tests
gtest test_play_cuda "$BIN/test_play_cuda"
gtest test_octreepack_cuda "$BIN/test_octreepack" --gtest_filter='*cuda*'
gtest test_core_cuda "$BIN/test_core" --gtest_filter='*cuda*'
gtest test_haar_cuda "$BIN/test_haar_cuda"
step lbsolve
OUT=$O/lbsolve ASSET=$built/../shared/assets/plants/oak_medium.glb timeout 420 sh bench/lbsolve/gpu.sh > "$O/lbsolve.log" 2>&1 || status=1
grep -E "^\| |passed|FAILED|bit-identical|byte-identical|wall" "$O/lbsolve.log" | head -120
date -u
exit $status
