#!/usr/bin/env bash
# gpu-quant.sh: the GPU checks and the sampling rate of the quantised Haar codec
# (canopy-haar --precision quant, .chaar 2.x) beside fp16 and fp32, in one device call.
#
# Here (from the repo root, after a Release build with -DCMAKE_CUDA_ARCHITECTURES=90):
#   build/bin/bench_haar OAK64.light.vdb --precision quant --write-chaar /tmp/hs/q.chaar   # 1% volume RMS
#   build/bin/bench_haar OAK64.light.vdb --precision fp16 --write-chaar /tmp/hs/b16.chaar
#   build/bin/bench_haar OAK64.light.vdb --write-chaar /tmp/hs/b32.chaar
#   (OAK64.light.vdb: canopy-voxelize oak_medium.glb --resolution 64 | canopy-lbsolve, the defaults)
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{bench_haar_gpu,test_haar_cuda,test_play_cuda,\
#      test_octreepack} -- /tmp/hs/q.chaar /tmp/hs/b16.chaar /tmp/hs/b32.chaar OAK64.light.vdb
# There:  [FILES="q b16 b32"] bash bench/gpu-quant.sh       (.gpu carried; logs and tables under $OUT)
#   1. CUDA tests: test_haar_cuda on the oak's real light and on the synthetic field (decode and
#      sampling, GPU == CPU bit for bit, fp32, fp16 and quant), test_play_cuda and test_octreepack's
#      device sampling (sampler_checks in gpu-common.sh; the float sampler runs through sumTerms).
#   2. bench_haar_gpu on the three files, twice in turn: compressed vs a float4 texture vs a plain
#      array, GPU samples checked against the CPU's.
set -u
source "$(dirname "$0")/gpu-common.sh"
S=$B/share
step tests
sampler_checks "$S/oak64.light.vdb"
gtest test_haar_cuda_synthetic "$BIN/test_haar_cuda"
step bench_haar_gpu
for round in 1 2; do
  for p in ${FILES:-q b16 b32}; do
    timeout 200 bench_haar_gpu "$S/$p.chaar" > "$O/bench_haar_gpu_${p}_$round.md" 2>&1 || status=1
    echo "--- $p round $round"
    grep -E "all 19|check:|compressed on device" "$O/bench_haar_gpu_${p}_$round.md"
  done
done
step end
exit $status
