#!/usr/bin/env bash
# gpu-play-skip.sh: issue 6's GPU checks and frame times for the empty-block skip (cone.h
# emptyRunEnd; bench/play/NOTES.md, fifth round), in one device call.
#
# Here (repo root, Release build with -DCMAKE_CUDA_ARCHITECTURES=90; the grove from
# `make -C pipelines scene RESOLUTION=64 DEVICE=cpu BIN=$PWD/build/bin O=/tmp/grove`, copied to
# /tmp/grove-in/grove.canopy):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{test_play_cuda,bench-play,canopy-play} -- ../shared /tmp/grove-in
# There:  bash bench/gpu-play-skip.sh  (.gpu carried)
#   tests: test_play_cuda: GPU frames against the CPU reference, quarter cache against full cache.
#   play:  bench-play, 1920x1080, 1 GiB cache, FRAMES (120) frames, the variants in PLAY_VARIANTS
#          (default: the skip, and without it; each scene's last frame is compared with the first
#          variant's: RMS). PREV_BIN=bench-play-prev (an earlier build's, bundled under that name):
#          the same runs with it after, for an A/B comparison on one machine.
#   PROFILE=1: Nsight Compute on one orbit frame's pixel kernel, where ncu is installed (needs the
#          forest that the play phase writes: with PHASES=tests only, a 2-frame play run writes
#          it). PROFILE_BIN=canopy-play-lineinfo (a canopy-play whose render_cuda.cu was compiled
#          with -lineinfo) adds the table per source line (source-cuda.csv, source-sass.csv).
set -u
source "$(dirname "$0")/gpu-common.sh"
PHASES=${PHASES:-tests play}
if has tests; then
  step tests
  gtest test_play_cuda "$BIN/test_play_cuda"
fi
if has play || [[ ${PROFILE:-0} = 1 ]]; then
  step play
  has play || FRAMES=2
  extra=()
  [[ -e $B/share/grove-in/grove.canopy ]] && extra=(--extra grove="$B/share/grove-in/grove.canopy")
  timeout 400 bench-play "$O/bench" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
    ${PLAY_VARIANTS:---shadows map --shadows map-noskip} "${extra[@]}" 2> "$O/bench_play.err" | tee "$O/bench_play.md" || status=1
  has play && for n in plant forest-orbit forest-walk grove; do [[ -e $O/bench/$n.png ]] && cp "$O/bench/$n.png" "$O/play-$n.png"; done
  cp "$O/bench/results.json" "$O/bench_play.json" 2>/dev/null
  if [[ -n ${PREV_BIN:-} ]]; then  # the same runs with an earlier build's bench-play (A/B on one machine)
    step "play with $PREV_BIN"
    timeout 400 "$PREV_BIN" "$O/bench-prev" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
      ${PLAY_VARIANTS:---shadows map --shadows map-noskip} "${extra[@]}" 2> "$O/bench_play_prev.err" | tee "$O/bench_play_prev.md" || status=1
    rm -rf "$O/bench-prev"
  fi
fi
if [[ ${PROFILE:-0} = 1 ]]; then
  step profile
  profile_play_orbit "${PROFILE_BIN:-canopy-play}" "$O/bench/forest.canopy"
  [[ -e $O/prof.ncu-rep ]] && tar cJf "$O/profile.tar.xz" -C "$O" prof.ncu-rep source-sass.csv source-both.csv && rm -f "$O"/prof.ncu-rep "$O"/source-*.csv
fi
rm -rf "$O/bench"
date -u
[[ $status = 0 ]] && rm -f "$O"/test_*.log
exit $status
