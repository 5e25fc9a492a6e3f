#!/usr/bin/env bash
# gpu-run.sh: canopy-play's GPU checks and benchmark in ONE device call, from a bundle.
#
# Here (the checkout the binaries were built in, Release, CUDA arch 90):
#   ../shared/scripts/bundle-libs DIR/canopy.tar.xz build/bin/{test_play_cuda,bench-play,canopy-play}
#   cp bench/play/gpu.sh bench/play/gpu-run.sh DIR/; cp grove.canopy DIR/   (optional: the grove)
# There (DIR carried):  bash DIR/gpu-run.sh DIR        (logs under $OUT)
#
# test_play_cuda writes its scenes under the build folder it was compiled in (CANOPY_BINARY_DIR,
# an absolute path, BUILT_AT below): the folder is created on the GPU host.
set -u
dir=${1:?bundle folder}
B=/tmp/canopy-play-bundle
mkdir -p "$B" && tar xJf "$dir/canopy.tar.xz" -C "$B"
export PATH=$B/bin:$PATH LD_LIBRARY_PATH=$B/lib BIN=$B/bin
mkdir -p "${BUILT_AT:?set BUILT_AT to the build folder test_play_cuda was compiled in}/tests/play/tmp"
[[ -f $dir/grove.canopy ]] && export GROVE=$dir/grove.canopy
W=/tmp/play-gpu-logs
mkdir -p "$W"
nvidia-smi > "$W/nvidia-smi.txt" 2>&1
OUT=$W bash "$dir/gpu.sh" > "$W/gpu.log" 2>&1
echo "gpu.sh rc=$?" >> "$W/gpu.log"
tail -40 "$W/gpu.log"
for s in plant forest-orbit forest-walk grove; do cp "$W/bench/$s.png" "$OUT/" 2>/dev/null; done
tar czf "$OUT/logs.tgz" -C "$W" --exclude='*.canopy' --exclude='*.png' --exclude='frames' .
