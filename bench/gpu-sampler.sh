#!/usr/bin/env bash
# gpu-sampler.sh: the GPU checks and measurements of the weighted-sum Haar point sampler, in one device call.
#
# Here (from the repo root, after a Release build with -DCMAKE_CUDA_ARCHITECTURES=90):
#   build/bin/bench_haar OAK64.light.vdb --write-chaar /tmp/hs/b32.chaar            # fp32, 1% volume RMS
#   build/bin/bench_haar OAK64.light.vdb --precision fp16 --write-chaar /tmp/hs/b16.chaar
#   (OAK64.light.vdb: canopy-voxelize oak_medium.glb --resolution 64 | canopy-lbsolve, the defaults)
#   cp PREVIOUS_BUILD/bin/bench-play /tmp/hs/bench-play-old       # the same benchmark before the change
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{bench_haar_gpu,test_haar_cuda,test_play_cuda,\
#      test_octreepack,test_core,bench-play} /tmp/hs/bench-play-old -- /tmp/hs/b32.chaar /tmp/hs/b16.chaar \
#      OAK64.light.vdb GROVE.canopy
# There:  bash bench/gpu-sampler.sh       (.gpu carried; logs and tables under $OUT)
#   1. CUDA tests: test_haar_cuda on the oak's real light (decode and sampling, GPU == CPU bit for bit),
#      test_core (halfToFloat and halfValue on the device for every half),
#      test_play_cuda, test_octreepack's device sampling.
#   2. bench_haar_gpu on both .chaar files: the sampler, a float4 texture and a plain array (GPU
#      samples checked against the CPU's). At 9e53285 it also timed the previous sampler and the
#      one-64-bit-loop form (bench/RESULTS.md); those copies were removed after.
#   3. bench-play on the grove, --light fast and exact, previous and new build alternately.
set -u
source "$(dirname "$0")/gpu-common.sh"
S=$B/share
step tests
sampler_checks "$S/oak64.light.vdb"
gtest test_core_cuda "$BIN/test_core" --gtest_filter="*cuda*"
step bench_haar_gpu
for p in 32 16; do
  timeout 200 bench_haar_gpu "$S/b$p.chaar" > "$O/bench_haar_gpu_fp$p.md" 2>&1 || status=1
  cat "$O/bench_haar_gpu_fp$p.md"
done
step play
for round in 1 2; do
  for v in old new; do
    exe=bench-play; [[ $v = old ]] && exe=bench-play-old
    timeout 200 $exe "/tmp/bp-$v" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 --only-extra \
      --shadows map --shadows map-exact --extra grove="$S/grove.canopy" 2> "$O/play-$v.err" > "/tmp/bp-$v.md" || status=1
    echo "--- $v round $round"; grep -E "^\| " "/tmp/bp-$v.md" | head -12
  done
done
cp /tmp/bp-new.md "$O/bench_play_new.md"; cp /tmp/bp-old.md "$O/bench_play_old.md"
cmp /tmp/bp-new/grove.png /tmp/bp-old/grove.png && echo "grove frames (fast): identical PNG"
ls /tmp/bp-new/ | head
date -u
exit $status
