#!/usr/bin/env bash
# gpu-haar-light.sh: the GPU checks and measurements of format 1.1's Haar light, in one device call.
#
# Here (from the repo root, after a Release build with -DCMAKE_CUDA_ARCHITECTURES=90):
#   make -C pipelines scene RESOLUTION=64 DEVICE=cpu O=/tmp/grove     # the grove's lattices and light
#   (cd /tmp/grove/scene && for i in 0 1 2; do canopy-haar -q grove.mesh$i.light.vdb --threshold 0.05 \
#      --precision fp16 -o grove.mesh$i.h16.light.chaar; done &&
#    sed 's/\.light\.chaar/.h16.light.chaar/g' grove.lit.scene.json > grove.h16.scene.json &&
#    sed 's/\.light\.chaar/.light.vdb/g' grove.lit.scene.json > grove.f16.scene.json)
#   mkdir -p /tmp/grove-in && cp /tmp/grove/scene/{grove.mesh?.density.vdb,grove.mesh?.light.vdb,\
#      grove.mesh?.h16.light.chaar,grove.?16.scene.json,grove.scenelight.vdb} /tmp/grove-in/
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{canopy-*,test_core,test_haar_cuda,\
#      test_lbsolve_cuda,test_octreepack,test_play_cuda,bench-play,bench-light-packing} -- ../shared /tmp/grove-in
# There:  bash bench/gpu-haar-light.sh       (.gpu carried; logs and tables under $OUT)
#   1. CUDA tests: test_play_cuda (GPU frames vs CPU, the Haar-lit forest among them), test_octreepack's
#      device sampling, test_core, test_haar_cuda, test_lbsolve_cuda (CANOPY_UNROLL moved to hd.h).
#   2. bench-play 1920x1080, 1 GiB cache, shadow map: plant, forest, and the grove packed twice from
#      the same lbsolve light: from the light VDBs (float16 items only) and from .chaar files (fp16,
#      threshold 0.05: float16 items + Haar pages); each with --light fast (map) and --light exact
#      (map-exact: the Haar pages at the finest level). PLAY_VARIANTS overrides the variants.
#   3. bench-light-packing on oak_medium at 128^3 (voxelised and lit on the GPU here).
set -u
source "$(dirname "$0")/gpu-common.sh"
step tests
gtest test_play_cuda "$BIN/test_play_cuda"
gtest test_octreepack_cuda "$BIN/test_octreepack" --gtest_filter='*cuda*'
gtest test_core_cuda "$BIN/test_core" --gtest_filter='*cuda*'
gtest test_haar_cuda "$BIN/test_haar_cuda"
[[ ${SKIP_LBSOLVE:-0} = 1 ]] || gtest test_lbsolve_cuda "$BIN/test_lbsolve_cuda"  # SKIP_LBSOLVE=1 when lbsolve is unchanged
step grove
G=$B/share/grove-in
for v in f16 h16; do
  (cd "$G" && canopy-octreepack -q --scene grove.$v.scene.json --scene-light grove.scenelight.vdb --scene-light-grid B00 \
     -o "$O/grove-$v.canopy") || status=1
done
ls -l "$O"/grove-*.canopy
step bench-play
timeout 300 bench-play "$O/bench" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
  ${PLAY_VARIANTS:---shadows map --shadows map-exact} \
  --extra grove-f16="$O/grove-f16.canopy" --extra grove-h16="$O/grove-h16.canopy" 2> "$O/bench_play.err" | tee "$O/bench_play.md" || status=1
cp "$O/bench/grove-h16.png" "$O/play-grove-h16.png" 2>/dev/null
rm -f "$O"/grove-*.canopy
[[ ${SKIP_LIGHT_PACKING:-0} = 1 ]] && { date -u; exit $status; }  # SKIP_LIGHT_PACKING=1: stop after the frames
step light-packing
W=/tmp/lp; mkdir -p $W
canopy-voxelize "$built/../shared/assets/plants/oak_medium.glb" -o $W/oak128.density.vdb --resolution 128 -q || status=1
canopy-lbsolve $W/oak128.density.vdb -o $W/oak128.light.vdb --device cuda -q || status=1
timeout 300 bench-light-packing $W/work $W/oak128.density.vdb $W/oak128.light.vdb --thresholds 0,0.01,0.03,0.05,0.1 \
  2> "$O/light_packing.err" | tee "$O/light_packing.md" || status=1
date -u
exit $status
