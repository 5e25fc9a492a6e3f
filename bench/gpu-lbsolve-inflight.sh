#!/usr/bin/env bash
# gpu-lbsolve-inflight.sh: the GPU checks and measurements of 2026-12-02's afternoon session (issue 3,
# bench/lbsolve/NOTES.md, fourth round; issue 6, bench/play/NOTES.md, fourth round), in one device
# call: several lbsolve solves in flight per GPU (solver.h, CudaRun) and the player's step without
# its per-hit segment array. (Earlier runs also compared variants of the pull kernel since removed,
# both no faster: rows in a scattered order at 5803f29, aligned loads with shuffles at 6cb7807.)
#
# Here (repo root, Release build with -DCMAKE_CUDA_ARCHITECTURES=90; the grove from
# `make -C pipelines scene RESOLUTION=64 DEVICE=cpu BIN=$PWD/build/bin O=/tmp/grove`, copied to
# /tmp/grove-in/grove.canopy):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{canopy-voxelize,canopy-lbsolve,\
#      test_lbsolve_cuda,bench_lbsolve,bench_lbsolve_streams,test_play_cuda,bench-play} -- ../shared /tmp/grove-in
# There:  PHASES="tests dense streams solves tool play" bash bench/gpu-lbsolve-inflight.sh  (.gpu carried)
#   tests:   test_lbsolve_cuda: every exact scheme bit for bit against the CPU, with 1, 3 and 8 solves
#            in flight; test_play_cuda (GPU frames against the CPU reference).
#   dense:   bench_lbsolve, synthetic plant 128^3 and 256^3 (DENSE_FILL=plant,full: and the full box),
#            pull and pull-fused, 1 and 3 solves in flight: node updates/s and the fraction of the
#            copy bandwidth.
#   streams: bench_lbsolve_streams (the traffic alone, per layout: the ceiling for each kernel).
#   solves:  the 57 solves of the synthetic 128^3 plant and of oak_medium at 128^3, shift and pull,
#            1..4 in flight.
#   tool:    canopy-lbsolve on the oak at 128^3, --solves-per-gpu 1..4: wall time, and the light files
#            must be byte-identical.
set -u
source "$(dirname "$0")/gpu-common.sh"
PHASES=${PHASES:-tests dense streams solves tool}
ASSET=$built/../shared/assets/plants/oak_medium.glb
if has tests; then
  step tests
  gtest test_lbsolve_cuda "$BIN/test_lbsolve_cuda"
  grep -E "in flight|oak 40" "$O/test_lbsolve_cuda.log" | head -40
  [[ -x $BIN/test_play_cuda ]] && gtest test_play_cuda "$BIN/test_play_cuda"
fi
if has dense; then
  # PREV_BIN (e.g. bench_lbsolve-prev, an earlier build bundled under that name): the same rows
  # with it after the current build's, for an A/B comparison on one machine
  for b in bench_lbsolve ${PREV_BIN:-}; do
    step "dense ($b)"
    timeout 300 "$b" --device cuda --sizes 128,256 --fill "${DENSE_FILL:-plant}" \
      --schemes "${DENSE_SCHEMES:-pull,pull-fused}" --in-flight "${DENSE_IN_FLIGHT:-1,3}" --iterations 400 \
      --solves-sizes "" > "$O/bench_dense_$b.md" 2>&1 || status=1
    grep -E "copy|^\| (plant|full)" "$O/bench_dense_$b.md"
  done
fi
if has streams; then
  step streams
  timeout 120 bench_lbsolve_streams --sizes 128,256 > "$O/bench_streams.md" 2>&1 || status=1
  grep -E "^\|" "$O/bench_streams.md" | head -30
fi
if has solves || has tool; then
  canopy-voxelize "$ASSET" -o "$O/oak128.density.vdb" --resolution 128 -q || status=1
fi
if has solves; then
  step solves
  timeout 400 bench_lbsolve --device cuda --sizes "" --schemes shift,pull --in-flight 1,2,3,4 --solves-sizes 128 \
    --lattices "$O/oak128.density.vdb" > "$O/bench_solves.md" 2>&1 || status=1
  grep -E "^\| " "$O/bench_solves.md"
fi
if has tool; then
  step tool
  for k in 1 2 3 4; do
    t0=$(date +%s.%N)
    canopy-lbsolve "$O/oak128.density.vdb" -o "$O/oak128.k$k.light.vdb" --device cuda --solves-per-gpu $k -q --json \
      > "$O/lbsolve_k$k.json" || status=1
    t1=$(date +%s.%N)
    echo "canopy-lbsolve oak128 --solves-per-gpu $k: $(awk "BEGIN{printf \"%.3f\", $t1 - $t0}") s wall (process)," \
      "report seconds $(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["seconds"])' "$O/lbsolve_k$k.json")"
  done
  for k in 2 3 4; do
    cmp -s "$O/oak128.k1.light.vdb" "$O/oak128.k$k.light.vdb" && echo "light file k=$k: byte-identical to k=1" ||
      { echo "FAILED: light file k=$k differs from k=1"; status=1; }
  done
  rm -f "$O"/oak128.*.light.vdb
fi
rm -f "$O/oak128.density.vdb"
if has play; then
  step play
  extra=()
  [[ -e $B/share/grove-in/grove.canopy ]] && extra=(--extra grove="$B/share/grove-in/grove.canopy")
  timeout 300 bench-play "$O/bench" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
    ${PLAY_VARIANTS:---shadows map} "${extra[@]}" 2> "$O/bench_play.err" | tee "$O/bench_play.md" || status=1
  for n in forest-orbit grove; do [[ -e $O/bench/$n.png ]] && cp "$O/bench/$n.png" "$O/play-$n.png"; done
  rm -rf "$O/bench"
fi
date -u
[[ $status = 0 ]] && rm -f "$O"/test_*.log
exit $status
