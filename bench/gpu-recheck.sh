#!/usr/bin/env bash
# gpu-recheck.sh: a short recheck on the GPU host (from the repo root, the bundle in .gpu/, see
# bench/RESULTS.md): fp16 conversion on the device, haar CUDA decode and sampling fp32/fp16 on
# oak_medium's real light.
set -u
B=/tmp/b; mkdir -p $B && tar xJf .gpu/canopy.tar.xz -C $B; export LD_LIBRARY_PATH=$B/lib
W=/tmp/w; mkdir -p $W; nvidia-smi -L; date -u
$B/bin/test_core --gtest_filter='*cuda*' 2>&1 | grep -E "OK|FAILED|PASSED|SKIPPED"
$B/bin/canopy-voxelize $B/share/oak_medium.glb -o $W/oak64.density.vdb --resolution 64 -q
$B/bin/canopy-lbsolve $W/oak64.density.vdb -o $W/oak64.light.vdb --device cuda -q
CANOPY_HAAR_LIGHT_VDB=$W/oak64.light.vdb $B/bin/test_haar_cuda 2>&1 | grep -E "OK|FAILED|PASSED|SKIPPED"
for p in fp32 fp16; do
  echo "== $p"
  $B/bin/bench_haar $W/oak64.light.vdb --precision $p --write-chaar $W/oak.$p.chaar 2>/dev/null | grep -E "ratio vs dense|same max error|\.chaar at|chaar / ZFP"
  $B/bin/bench_haar_gpu $W/oak.$p.chaar 2>/dev/null | grep -E "all 19|compressed on device"
done
