#!/usr/bin/env bash
# gpu-recheck.sh: a short recheck on the GPU host (from the repo root, the bundle in .gpu/, see
# bench/RESULTS.md): fp16 conversion on the device, haar CUDA decode and sampling fp32/fp16 on
# oak_medium's real light. Exits non-zero if a step fails or a CUDA test fails or skips.
set -u
status=0
B=/tmp/b; mkdir -p $B && tar xJf .gpu/canopy.tar.xz -C $B; export LD_LIBRARY_PATH=$B/lib
W=/tmp/w; mkdir -p $W; nvidia-smi -L; date -u
gtest() {  # gtest LOG BINARY [args]: runs a gtest binary, shows its verdicts, fails on failure or skip
  local log=$W/$1; shift
  "$@" > "$log" 2>&1 || status=1
  grep -E "OK|FAILED|PASSED|SKIPPED" "$log"
  ! grep -q "SKIPPED" "$log" || status=1
}
gtest test_core.log $B/bin/test_core --gtest_filter='*cuda*'
$B/bin/canopy-voxelize $B/share/oak_medium.glb -o $W/oak64.density.vdb --resolution 64 -q || status=1
$B/bin/canopy-lbsolve $W/oak64.density.vdb -o $W/oak64.light.vdb --device cuda -q || status=1
CANOPY_HAAR_LIGHT_VDB=$W/oak64.light.vdb gtest test_haar_cuda.log $B/bin/test_haar_cuda
for p in fp32 fp16; do
  echo "== $p"
  $B/bin/bench_haar $W/oak64.light.vdb --precision $p --write-chaar $W/oak.$p.chaar > $W/bench_haar.$p.md 2> /dev/null || status=1
  grep -E "ratio vs dense|same max error|\.chaar at|chaar / ZFP" $W/bench_haar.$p.md
  $B/bin/bench_haar_gpu $W/oak.$p.chaar > $W/bench_haar_gpu.$p.md 2> /dev/null || status=1
  grep -E "all 19|compressed on device" $W/bench_haar_gpu.$p.md
done
exit $status
