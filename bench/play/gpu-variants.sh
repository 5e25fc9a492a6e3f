#!/usr/bin/env bash
# gpu-variants.sh: bench-play builds side by side on one GPU (A/B in one device call), optionally
# Nsight Compute on one forest-orbit frame of a canopy-play build, and its SASS.
#
# Here: bench/play/variant.sh NAME "NVCC FLAGS" for each variant (render_cuda.cu rebuilt with the
# flags), then
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{bench-play,canopy-play,test_play_cuda}* 
# There (.gpu carried):
#   VARIANTS="'' -fast" [FRAMES=60] [PROFILE_BIN=canopy-play-NAME] [TESTS="test_play_cuda ..."] bash bench/play/gpu-variants.sh
# The tables come back as files and on stdout, everything else in $OUT/logs.tar.xz.
set -u
source "$(dirname "$0")/../gpu-common.sh"
for t in ${TESTS:-}; do step "$t"; gtest "$t" "$BIN/$t"; done
run=0
extra=()  # the grove, where bundled (see bench/gpu-play-skip.sh for how it is made)
[[ -e $B/share/grove-in/grove.canopy ]] && extra=(--extra grove="$B/share/grove-in/grove.canopy")
for v in ${VARIANTS:-''}; do
  v=${v//\'/}
  run=$((run + 1)) r="$run$v"  # a variant may run twice (before and after the others)
  step "bench-play$v (run $run)"
  timeout 300 "bench-play$v" "$O/bench$r" --device cuda --size 1920x1080 --frames "${FRAMES:-60}" --cache-mb 1024 \
    ${PLAY_VARIANTS:---shadows map} "${extra[@]}" 2> "$O/bench_play$r.err" | tee "$O/bench_play$r.md" || status=1
  [[ ${PNGS:-0} = 1 && $run = 1 ]] && for n in plant forest-orbit forest-walk grove; do [[ -e $O/bench$r/$n.png ]] && cp "$O/bench$r/$n.png" "$O/play-$n.png"; done
  [[ -n ${KEEP_SCENE:-} ]] || { mkdir -p "$O/scene" && cp "$O/bench$r/forest.canopy" "$O/scene/" && KEEP_SCENE=$O/scene/forest.canopy; }
done
if [[ -n ${PROFILE_BIN:-} ]]; then
  step "profile $PROFILE_BIN"
  profile_play_orbit "$PROFILE_BIN" "$KEEP_SCENE"
  CUOBJDUMP=$(command -v cuobjdump || ls /usr/local/cuda/bin/cuobjdump 2>/dev/null || true)
  [[ -n $CUOBJDUMP ]] && "$CUOBJDUMP" -sass "$BIN/$PROFILE_BIN" > "$O/sass.txt" 2>&1
fi
rm -rf "$O"/bench*/ "$O/scene"
date -u
# back: the tables, the PNGs (PNGS=1: the first run's), one archive of the rest (the device tool
# returns at most 8 files of 16 MiB)
(cd "$O" && tar cJf logs.tar.xz --exclude='*.png' --exclude='bench_play*.md' * && find . -maxdepth 1 -type f ! -name logs.tar.xz ! -name '*.png' ! -name 'bench_play*.md' -delete)
exit $status
