#!/usr/bin/env bash
# gpu-pull-sun.sh: the GPU checks and measurements of 2026-12-01's second session, in one device call:
# the dense "pull" lbsolve scheme (pull_stream.h), the scattered-only sun bases (beam.h; the
# player's shading now scales them by the sun radiance), and the player's quality dials.
#
# Here (from the repo root, after a Release build with -DCMAKE_CUDA_ARCHITECTURES=90; the grove from
# `make -C pipelines scene RESOLUTION=64 DEVICE=cpu BIN=$PWD/build/bin O=/tmp/grove`, copied to
# /tmp/grove-in/grove.canopy):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{canopy-*,test_core,test_haar_cuda,\
#      test_lbsolve_cuda,test_octreepack,test_play_cuda,bench_lbsolve,bench_lbsolve_streams,bench-play} \
#      -- ../shared /tmp/grove-in
# There:  PHASES="tests lbsolve fused play" bash bench/gpu-pull-sun.sh   (.gpu carried; logs under $OUT)
#   tests:   test_play_cuda (GPU frames vs CPU, lit forests with and without the direct sun),
#            test_octreepack's device sampling, test_core, test_haar_cuda.
#   lbsolve: bench/lbsolve/gpu.sh: test_lbsolve_cuda (every scheme, pull included, bit for bit against
#            the CPU), bench_lbsolve_streams, bench_lbsolve (shift, shift-split, push, pull; plant and
#            full box at 128^3 and 256^3; 57 solves), canopy-lbsolve on oak_medium at 128^3 per scheme.
#   fused:   bench_lbsolve push, pull, pull-fused (dense rows only) and test_lbsolve_cuda's oak case
#            (pull-fused held to its bound): what the unfused collision arithmetic costs pull.
#   play:    bench-play 1920x1080, 1 GiB cache: plant, forest orbit and walk, and the grove, with the
#            default and the quality dials (--stop-opacity 0.99, --step 1, --lod-bias -1), each
#            last frame compared with the default's.
set -u
source "$(dirname "$0")/gpu-common.sh"
PHASES=${PHASES:-tests lbsolve}
if has tests; then
  step tests
  gtest test_play_cuda "$BIN/test_play_cuda"
  gtest test_octreepack_cuda "$BIN/test_octreepack" --gtest_filter='*cuda*'
  gtest test_core_cuda "$BIN/test_core" --gtest_filter='*cuda*'
  gtest test_haar_cuda "$BIN/test_haar_cuda"
fi
if has lbsolve; then
  step lbsolve
  OUT=$O/lbsolve ASSET=$built/../shared/assets/plants/oak_medium.glb timeout 420 sh bench/lbsolve/gpu.sh > "$O/lbsolve.log" 2>&1 || status=1
  grep -E "^\| |passed|FAILED|bit-identical|byte-identical|wall" "$O/lbsolve.log" | head -120
fi
if has fused; then
  step fused
  gtest test_lbsolve_cuda_oak "$BIN/test_lbsolve_cuda" --gtest_filter='*RealOak*'
  grep -E "oak 40" "$O/test_lbsolve_cuda_oak.log"
  timeout 300 bench_lbsolve --device cuda --sizes 128,256 --fill plant,full --schemes push,pull,pull-fused --iterations 400 \
    --solves-sizes "" > "$O/bench_lbsolve_fused.md" 2>&1 || status=1
  grep -E "copy|^\| (plant|full)" "$O/bench_lbsolve_fused.md"
fi
if has play; then
  step play
  extra=()
  [[ -e $B/share/grove-in/grove.canopy ]] && extra=(--extra grove="$B/share/grove-in/grove.canopy")
  timeout 420 bench-play "$O/bench" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
    ${PLAY_VARIANTS:---shadows map --shadows map-stop99 --shadows map-step1 --shadows map-lod1 --shadows map-stop99-step1} \
    "${extra[@]}" 2> "$O/bench_play.err" | tee "$O/bench_play.md" || status=1
  for n in plant forest-orbit forest-walk grove; do [[ -e $O/bench/$n.png ]] && cp "$O/bench/$n.png" "$O/play-$n.png"; done
  rm -rf "$O/bench"
fi
date -u
# Only a few files come back from the device: the tables and frames stay, passing tests' logs go.
[[ $status = 0 ]] && rm -f "$O"/test_*.log "$O"/bench_play.err
exit $status
