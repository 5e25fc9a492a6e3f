#!/usr/bin/env bash
# gpu-play-skip.sh: issue 6's GPU checks and frame times for the empty-block skip (cone.h
# emptyBlockBox; bench/play/NOTES.md, fifth round), in one device call.
#
# Here (repo root, Release build with -DCMAKE_CUDA_ARCHITECTURES=90; the grove from
# `make -C pipelines scene RESOLUTION=64 DEVICE=cpu BIN=$PWD/build/bin O=/tmp/grove`, copied to
# /tmp/grove-in/grove.canopy):
#   ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/{test_play_cuda,bench-play,canopy-play} -- ../shared /tmp/grove-in
# There:  bash bench/gpu-play-skip.sh  (.gpu carried)
#   1. test_play_cuda: GPU frames against the CPU reference, quarter cache against full cache.
#   2. bench-play, 1920x1080, 1 GiB cache, FRAMES (120) frames, the variants in PLAY_VARIANTS
#      (default: the skip, and without it for comparison; each scene's last frame is compared with
#      the first variant's: RMS).
#   3. PROFILE=1: Nsight Compute on one orbit frame's pixel kernel, where ncu is installed.
set -u
source "$(dirname "$0")/gpu-common.sh"
step tests
gtest test_play_cuda "$BIN/test_play_cuda"
step play
extra=()
[[ -e $B/share/grove-in/grove.canopy ]] && extra=(--extra grove="$B/share/grove-in/grove.canopy")
timeout 400 bench-play "$O/bench" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
  ${PLAY_VARIANTS:---shadows map --shadows map-noskip} "${extra[@]}" 2> "$O/bench_play.err" | tee "$O/bench_play.md" || status=1
for n in plant forest-orbit forest-walk grove; do [[ -e $O/bench/$n.png ]] && cp "$O/bench/$n.png" "$O/play-$n.png"; done
cp "$O/bench/results.json" "$O/bench_play.json" 2>/dev/null
if [[ ${PROFILE:-0} = 1 ]]; then
  step profile
  NCU=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
  if [[ -n $NCU ]]; then
    timeout 200 "$NCU" --kernel-name regex:'[Pp]ixel' --launch-skip 9 --launch-count 1 \
      --section SpeedOfLight --section Occupancy --section WarpStateStats --section LaunchStats --section MemoryWorkloadAnalysis \
      canopy-play "$O/bench/forest.canopy" --device cuda --size 1920x1080 --frames 10 --camera orbit:elevation=30,distance=55 \
      -o "$O/ncu-frame.exr" > "$O/ncu.txt" 2>&1 || echo "ncu failed (see ncu.txt)"
    grep -vE "^==PROF==" "$O/ncu.txt" | tail -80
  else
    echo "no ncu on this host"
  fi
fi
rm -rf "$O/bench" "$O"/ncu-frame*.exr
date -u
[[ $status = 0 ]] && rm -f "$O"/test_*.log
exit $status
