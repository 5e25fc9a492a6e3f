#!/usr/bin/env bash
# gpu-lbsolve-batch.sh: several solves per pull launch (solver.h, CudaRun::solvesPerLaunch;
# bench/lbsolve/NOTES.md, seventh round), in one device call.
#
# Here (repo root, Release build with -DCMAKE_CUDA_ARCHITECTURES=90):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{canopy-voxelize,canopy-lbsolve,\
#      test_lbsolve_cuda,bench_lbsolve} -- ../shared
# There:  PHASES="tests dense solves tool" bash bench/gpu-lbsolve-batch.sh  (.gpu carried)
#   tests:  test_lbsolve_cuda (every exact scheme against the CPU bit for bit; pull with 2, 19 and
#           32 solves per launch, 1 and 2 in flight).
#   dense:  bench_lbsolve, synthetic plant at DENSE_SIZES (128,256), pull and pull-fused, 1, 3 and 19
#           solves per launch (DENSE_PER_LAUNCH), one solver: node updates/s, fraction of copy.
#   solves: the 57 solves of the synthetic 128^3 plant and of oak_medium at 128^3: shift, and pull
#           with 1 and 19 per launch.
#   tool:   canopy-lbsolve on the oak at 128^3: shift (the default), pull, pull with 19 per launch:
#           wall times, and the three light files must be byte-identical.
set -u
source "$(dirname "$0")/gpu-common.sh"
PHASES=${PHASES:-tests dense solves tool}
ASSET=$built/../shared/assets/plants/oak_medium.glb
if has tests; then
  step tests
  gtest test_lbsolve_cuda "$BIN/test_lbsolve_cuda"
  grep -E "per launch|stop after|oak 40" "$O/test_lbsolve_cuda.log" | head -40
fi
if has dense; then
  for b in bench_lbsolve ${PREV_BIN:-}; do
    step "dense ($b)"
    args=(--device cuda --sizes "${DENSE_SIZES:-128,256}" --fill plant --schemes "${DENSE_SCHEMES:-pull,pull-fused}"
          --iterations "${DENSE_ITERATIONS:-400}" --solves-sizes "")
    args+=(--per-launch "${DENSE_PER_LAUNCH:-1,3,19}")  # PREV_BIN: a build that has --per-launch (12c0f90 on)
    timeout 400 "$b" "${args[@]}" > "$O/bench_dense_$b.md" 2>&1 || status=1
    grep -E "copy|^\| plant" "$O/bench_dense_$b.md"
  done
fi
if has solves || has tool; then
  canopy-voxelize "$ASSET" -o "$O/oak128.density.vdb" --resolution 128 -q || status=1
fi
if has solves; then
  step solves
  timeout 400 bench_lbsolve --device cuda --sizes "" --schemes shift,pull --per-launch 1,19 --solves-sizes 128 \
    --lattices "$O/oak128.density.vdb" > "$O/bench_solves.md" 2>&1 || status=1
  grep -E "^\| " "$O/bench_solves.md"
fi
if has tool; then
  step tool
  run_tool() {  # run_tool NAME ARGS...
    local name=$1; shift
    local t0 t1
    t0=$(date +%s.%N)
    canopy-lbsolve "$O/oak128.density.vdb" -o "$O/oak128.$name.light.vdb" --device cuda "$@" -q --json \
      > "$O/lbsolve_$name.json" || status=1
    t1=$(date +%s.%N)
    echo "canopy-lbsolve oak128 $*: $(awk "BEGIN{printf \"%.3f\", $t1 - $t0}") s wall (process)," \
      "report seconds $(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["seconds"])' "$O/lbsolve_$name.json")"
  }
  run_tool shift
  run_tool pull --cuda-scheme pull
  run_tool pull19 --cuda-scheme pull --solves-per-launch 19
  for k in pull pull19; do
    cmp -s "$O/oak128.shift.light.vdb" "$O/oak128.$k.light.vdb" && echo "light file $k: byte-identical to shift" ||
      { echo "FAILED: light file $k differs from shift"; status=1; }
  done
  rm -f "$O"/oak128.*.light.vdb
fi
rm -f "$O/oak128.density.vdb"
date -u
[[ $status = 0 ]] && rm -f "$O"/test_*.log
exit $status
