#!/usr/bin/env bash
# gpu-lighting.sh: the lighting's GPU checks and timings on the GPU host, in one call (from the repo
# root, with the bundle at .gpu/canopy.tar.xz carried; logs and figures under $OUT):
#   1. the CUDA tests: lbsolve (every scheme bit-identical to the CPU, with the Beer-Lambert
#      collision's exp computed on the device), play (GPU frame vs CPU reference, including the
#      19-base scene light moving with the sun), core, octreepack, haar on oak_medium's real light;
#   2. lbsolve: node updates/s and the fraction of the copy bandwidth of the pull and shift schemes
#      (synthetic plant and full box, 128^3 and 256^3), and oak_medium at 128^3 end to end (57
#      solves) with the default collision and with --collision linear (the exp's cost);
#   3. bench-play on the synthetic scenes at 1920x1080, 120 frames, 1 GiB cache (frame times);
#   4. the grove scene through the Make rules on the GPU (voxelize, lbsolve, lbsolve --scene,
#      haar, octreepack with the 19 scene bases) and played at 1080p.
# Here:   cmake --build build && ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/* -- ../shared
# There:  bash bench/gpu-lighting.sh            (PHASES="tests lbsolve play grove" by default; any subset)
#         SHADOWS="map cone" adds the shadow cones to the play and grove timings.
set -u
PHASES=${PHASES:-tests lbsolve play grove}
source bench/gpu-common.sh
if has tests; then
step tests
gtest test_lbsolve_cuda "$BIN/test_lbsolve_cuda"
gtest test_play_cuda "$BIN/test_play_cuda"
gtest test_core_cuda "$BIN/test_core" --gtest_filter='*cuda*'
gtest test_octreepack_cuda "$BIN/test_octreepack" --gtest_filter='*cuda*'
fi
W=/tmp/lighting; mkdir -p $W
if has lbsolve; then
step lbsolve
"$BIN/canopy-voxelize" "$B/share/shared/assets/plants/oak_medium.glb" -o $W/oak128.density.vdb -r 128 -q || status=1
"$BIN/canopy-voxelize" "$B/share/shared/assets/plants/oak_medium.glb" -o $W/oak64.density.vdb -r 64 -q || status=1
for c in beer-lambert linear; do
  "$BIN/canopy-lbsolve" $W/oak128.density.vdb -o $W/oak128.$c.light.vdb --device cuda --collision $c --json -q > $O/lbsolve_oak128_$c.json || status=1
  python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print(sys.argv[2], 'oak128 57 solves', round(r['seconds'],3), 's', r.get('node_updates_per_second'))" $O/lbsolve_oak128_$c.json $c
done
"$BIN/canopy-lbsolve" $W/oak64.density.vdb -o $W/oak64.light.vdb --device cuda -q || status=1
CANOPY_HAAR_LIGHT_VDB=$W/oak64.light.vdb gtest test_haar_cuda "$BIN/test_haar_cuda"
timeout 300 "$BIN/bench_lbsolve" --device cuda --sizes 128,256 --fill plant,full --schemes shift,pull --iterations 400 \
  --solves-sizes "" > $O/bench_lbsolve.md 2>&1 || status=1
grep -E "^\|" $O/bench_lbsolve.md | head -40
fi
shadowArgs=""; for m in ${SHADOWS:-map}; do shadowArgs="$shadowArgs --shadows $m"; done
if has play; then
step play
timeout 400 "$BIN/bench-play" $O/play --device cuda --size 1920x1080 --frames 120 --cache-mb 1024 $shadowArgs > $O/bench_play.md 2>&1 || status=1
grep -E "^\|" $O/bench_play.md | head -20
fi
if has grove; then
step grove
export PATH=$BIN:$PATH
timeout 400 make -C pipelines scene SCENE=$B/share/shared/assets/scenes/grove.glb BIN=$BIN O=$W/o DEVICE=cuda RESOLUTION=96 \
  > $O/grove_make.log 2>&1 || { status=1; tail -20 $O/grove_make.log; }
"$BIN/canopy-octreepack" info $W/o/scene/grove.canopy 2>&1 | grep -iE "scene light|version" | head -3
timeout 120 "$BIN/canopy-play" $W/o/scene/grove.canopy --device cuda --size 1920x1080 --frames 120 --cache-mb 1024 \
  --camera orbit:turns=0.5,elevation=20 --sun orbit:azimuth=40,elevation=30,turns=0.5 --json -q > $O/grove_play.json || status=1
python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print('grove 1080p', {k: r[k] for k in r if k in ('frame_ms_median','frame_ms_p95','first_complete_frame_s','scene_light_bases','sun_bases','lit_models')})" $O/grove_play.json
for m in ${SHADOWS:-map}; do
  [[ $m == map ]] && continue
  timeout 200 "$BIN/canopy-play" $W/o/scene/grove.canopy --device cuda --size 1920x1080 --frames 60 --cache-mb 1024 --shadows $m \
    --camera orbit:turns=0.5,elevation=20 --sun orbit:azimuth=40,elevation=30,turns=0.5 --json -q > $O/grove_play_$m.json || status=1
  python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print('grove 1080p', sys.argv[2], r['frame_ms_median'], r['frame_ms_p95'])" $O/grove_play_$m.json $m
done
"$BIN/canopy-play" $W/o/scene/grove.canopy --device cuda --size 640x360 -o $O/grove.png -q || status=1
fi
echo "status $status"
exit $status
