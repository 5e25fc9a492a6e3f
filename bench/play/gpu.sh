#!/bin/sh
# gpu.sh: canopy-play's checks and benchmark on a GPU host.
#   BIN=build/bin OUT=/tmp/play-gpu sh bench/play/gpu.sh
# 1. test_play_cuda: GPU frame vs CPU reference; quarter-size cache camera path vs full cache.
# 2. bench-play: 1920x1080 plant + 400-instance forest (orbit and walk), 1 GiB cache, cold start;
#    writes $OUT/bench/*.png, results.json and a Markdown table ($OUT/bench_play.md) for
#    bench/RESULTS.md. Set GROVE=path/to/grove.canopy to add the grove from the pipeline.
# 3. the forest walk again with a cache of 32 MiB (smaller than the forest's pages): it must play.
set -eu
: "${BIN:?set BIN to the folder with test_play_cuda and bench-play}"
: "${OUT:?set OUT to a folder for the logs}"
mkdir -p "$OUT"
"$BIN/test_play_cuda" 2>&1 | tee "$OUT/test_play_cuda.log"
grep -q '\[  PASSED  \] 2 tests' "$OUT/test_play_cuda.log" || { echo "gpu.sh: CUDA tests did not all pass (skipped or failed)" >&2; exit 1; }
EXTRA=""
if [ -n "${GROVE:-}" ]; then EXTRA="--extra grove=$GROVE"; fi
# shellcheck disable=SC2086
"$BIN/bench-play" "$OUT/bench" --device cuda --size 1920x1080 --frames 120 --cache-mb 1024 $EXTRA | tee "$OUT/bench_play.md"
"$BIN/bench-play" "$OUT/bench-small-cache" --device cuda --size 1920x1080 --frames 120 --cache-mb 32 | tee "$OUT/bench_play_small_cache.md"
mkdir -p "$OUT/frames"
"$BIN/canopy-play" "$OUT/bench/forest.canopy" --device cuda --size 1920x1080 --frames 60 -o "$OUT/frames/f_%04d.png" \
  --camera "$OUT/bench/forest-walk.json" --sun orbit:turns=0.2 --json > "$OUT/canopy_play_walk.json"
echo "gpu.sh: done; see $OUT/bench_play.md"
