#!/usr/bin/env bash
# compare-builds.sh OLD_BIN NEW_BIN OUT [cpu|cuda]: runs the same small chain with two builds and
# compares every output byte for byte, to show that a change that should not change behaviour (a
# code move, a split into named stages) does not.
#
# The chain, per build, under OUT/old and OUT/new:
#   - `make -C pipelines scene` on the shared grove (voxelize, lbsolve on the CPU, haar, octreepack
#     --scene) at RESOLUTION 32;
#   - `make -C pipelines plants` on aspen_small at RESOLUTION 24, DETAIL 96 (a format 2.0 file);
#   - canopy-play frames of both files on the given device (default cpu): orbit and close-up
#     cameras, both shadow methods, both light paths, stereo with the right eye reprojected, 2 bands.
# Compared: every .vdb, .chaar, .canopy and .exr (the JSON reports hold times and are left out).
# Exit 0 when all are identical, 1 otherwise (the differing files are listed).
#
#   bench/compare-builds.sh /tmp/old/bin build/bin /tmp/cmp
#   bench/compare-builds.sh old/bin new/bin "$OUT/cmp" cuda     # CUDA frames (packs still on CPU)
set -euo pipefail
[ $# -ge 3 ] || { sed -n 2,16p "$0" >&2; exit 2; }
OLD=$(cd "$1" && pwd)
NEW=$(cd "$2" && pwd)
OUT=$3
DEVICE=${4:-cpu}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
SHARED=${SHARED:-$(cd "$ROOT/.." && pwd)/shared}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

run_chain() {  # BIN DIR
  local bin=$1 dir=$2
  mkdir -p "$dir/aspen" "$dir/frames"
  ln -sf "$SHARED/assets/plants/aspen_small.glb" "$dir/aspen/aspen_small.glb"
  make -s -C "$ROOT/pipelines" scene BIN="$bin" O="$dir" SHARED="$SHARED" RESOLUTION=32 DEVICE=cpu >/dev/null
  make -s -C "$ROOT/pipelines" plants BIN="$bin" O="$dir" PLANTS="$dir/aspen" RESOLUTION=24 DETAIL=96 DEVICE=cpu >/dev/null
  local play="$bin/canopy-play --quiet --device $DEVICE --size 320x180 --converge"
  local scene=$dir/scene/grove.canopy plant=$dir/plants/aspen_small.canopy
  $play "$scene" -o "$dir/frames/scene-orbit.exr" --camera orbit:elevation=20
  $play "$scene" -o "$dir/frames/scene-low-cones.exr" --camera orbit:elevation=5,distance=12 --shadows cone
  $play "$scene" -o "$dir/frames/scene-exact.exr" --camera orbit:elevation=30 --light exact --ground none
  $play "$scene" -o "$dir/frames/scene-stereo-l.exr" --right-output "$dir/frames/scene-stereo-r.exr" --stereo 0.1 \
    --camera orbit:elevation=10,distance=10
  $play "$scene" -o "$dir/frames/scene-bands.exr" --camera orbit:elevation=20 --tiles 2
  $play "$plant" -o "$dir/frames/plant-near.exr" --camera orbit:elevation=5,distance=8
  $play "$plant" -o "$dir/frames/plant-exact.exr" --camera orbit:elevation=5,distance=8 --light exact --shadows cone
  $play "$plant" -o "$dir/frames/plant-f%d.exr" --frames 3 --camera orbit:turns=0.5 --sun orbit:turns=0.25
}

run_chain "$OLD" "$OUT/old"
run_chain "$NEW" "$OUT/new"

status=0 count=0
while IFS= read -r f; do
  count=$((count + 1))
  if ! cmp -s "$OUT/old/$f" "$OUT/new/$f"; then
    echo "differs: $f"
    status=1
  fi
done < <(cd "$OUT/old" && find . -type f \( -name '*.vdb' -o -name '*.chaar' -o -name '*.canopy' -o -name '*.exr' \) | sort)
[ "$count" -gt 0 ] || { echo "compare-builds: no outputs" >&2; exit 2; }
echo "compare-builds ($DEVICE): $count files compared, $([ $status = 0 ] && echo 'all identical' || echo 'some differ')"
exit $status
