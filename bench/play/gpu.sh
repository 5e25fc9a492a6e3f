#!/bin/sh
# gpu.sh: canopy-play's checks and benchmark on a GPU host.
#   BIN=build/bin OUT=/tmp/play-gpu sh bench/play/gpu.sh      [GROVE=path/to/grove.canopy]
# 1. test_play_cuda: GPU frames vs the CPU reference; quarter-size cache camera path vs full cache.
# 2. bench-play: 1920x1080, one cone per pixel, 1 GiB cache, cold start: the synthetic plant, the
#    400-instance forest (orbit and walk) and the grove when GROVE is set, each with the shadow map
#    (the default) and, for comparison, the per-sample shadow cones and no shadows. Writes
#    $OUT/bench/*.png, results.json and a Markdown table ($OUT/bench_play.md) for bench/RESULTS.md.
# 3. the scenes again with a cache of 32 MiB (less than the forest's file): they must play.
# FRAMES (default 120) and SHADOW_VARIANTS (default "--shadows map --shadows cone --shadows off";
# e.g. "--shadows map --shadows map-rows --shadows map-nocache --shadows map-nohold --shadows map-occ8")
# change the benchmark runs; SMALL_CACHE=0 skips step 3.
set -u
: "${BIN:?set BIN to the folder with test_play_cuda and bench-play}"
: "${OUT:?set OUT to a folder for the logs}"
FRAMES=${FRAMES:-120}
mkdir -p "$OUT"
"$BIN/test_play_cuda" > "$OUT/test_play_cuda.log" 2>&1
grep -E "OK|FAILED|PASSED|Failure|Expected|actual" "$OUT/test_play_cuda.log"
grep -q '\[  PASSED  \] 2 tests' "$OUT/test_play_cuda.log" || echo "gpu.sh: CUDA tests did not all pass (skipped or failed)" >&2
EXTRA=""
if [ -n "${GROVE:-}" ]; then EXTRA="--extra grove=$GROVE"; fi
# shellcheck disable=SC2086
"$BIN/bench-play" "$OUT/bench" --device cuda --size 1920x1080 --frames "$FRAMES" --cache-mb 1024 $EXTRA \
  ${SHADOW_VARIANTS:---shadows map --shadows cone --shadows off} 2> "$OUT/bench_play.err" | tee "$OUT/bench_play.md"
[ "${SMALL_CACHE:-1}" = 0 ] || "$BIN/bench-play" "$OUT/bench-small-cache" --device cuda --size 1920x1080 --frames "$FRAMES" --cache-mb 32 \
  2> "$OUT/bench_play_small_cache.err" | tee "$OUT/bench_play_small_cache.md"
echo "gpu.sh: done; see $OUT/bench_play.md"
