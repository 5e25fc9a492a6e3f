#!/bin/sh
# Runs the lbsolve checks that need a GPU: the CUDA-vs-CPU test (synthetic plants, odd sizes, an
# occupied boundary layer, the real oak at 40^3; every CUDA scheme), the traffic-only benchmark
# (bench_lbsolve_streams), then the benchmark: node
# updates/s of each scheme on the synthetic plant and on a fully occupied box at 128^3 and 256^3,
# the 57 solves of the synthetic plant (128^3; 256^3 with the shift schemes) and of oak_medium
# voxelised at 128^3, the tool itself on that oak (--device cuda, default scheme), and the CPU
# figure of the same host. About 3 minutes on one H100.
# Exits non-zero if a step fails or the CUDA tests were skipped.
# Usage: BIN=build/bin OUT=/some/log/dir [ASSET=.../oak_medium.glb] sh bench/lbsolve/gpu.sh
set -u
: "${BIN:?set BIN to the directory holding the built binaries (build/bin)}"
: "${OUT:?set OUT to a directory for the logs}"
ASSET=${ASSET:-$(dirname "$0")/../../../shared/assets/plants/oak_medium.glb}
ITERATIONS=${ITERATIONS:-400}
mkdir -p "$OUT"
nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1 || true
status=0
step() {  # step LOG COMMAND...: runs the command, keeps its output in $OUT/LOG and shows it
  log="$OUT/$1"
  shift
  "$@" > "$log" 2>&1 || { echo "gpu.sh: FAILED: $*" >> "$log"; status=1; }
  cat "$log"
}
step test_lbsolve_cuda.log "$BIN/test_lbsolve_cuda"
if grep -q "SKIPPED" "$OUT/test_lbsolve_cuda.log"; then
  echo "gpu.sh: the CUDA tests were skipped (no GPU visible?)"
  status=1
fi
step voxelize_oak128.log "$BIN/canopy-voxelize" "$ASSET" -o "$OUT/oak128.density.vdb" --resolution 128
# The memory traffic of the dense update alone, per layout and order (bench/lbsolve/NOTES.md).
step bench_lbsolve_streams.md "$BIN/bench_lbsolve_streams" --sizes 128,256
step bench_lbsolve_cuda.md "$BIN/bench_lbsolve" --device cuda --sizes 128,256 --fill plant,full \
  --schemes "${SCHEMES:-shift,shift-split,push,pull}" --iterations "$ITERATIONS" --solves-sizes 128 --lattices "$OUT/oak128.density.vdb"
# The 57 solves of the synthetic 256^3 plant with the shift schemes (push: ~50 s, see RESULTS.md).
step bench_lbsolve_cuda256.md "$BIN/bench_lbsolve" --device cuda --sizes "" --schemes shift,shift-split --solves-sizes 256
# The tool end to end on the oak (read, 57 solves, write), wall time, with each CUDA scheme; the
# light files of all schemes must be byte-identical (same bits, deterministic writer).
: > "$OUT/lbsolve_oak128_wall.txt"
for scheme in shift shift-split push pull; do
  t0=$(date +%s.%N)
  step "lbsolve_oak128_$scheme.json" "$BIN/canopy-lbsolve" "$OUT/oak128.density.vdb" -o "$OUT/oak128.$scheme.light.vdb" \
    --device cuda --cuda-scheme "$scheme" --json -q
  t1=$(date +%s.%N)
  echo "canopy-lbsolve oak128 --device cuda --cuda-scheme $scheme: $(awk "BEGIN{printf \"%.3f\", $t1 - $t0}") s wall (process, including I/O)" | tee -a "$OUT/lbsolve_oak128_wall.txt"
done
if cmp "$OUT/oak128.shift.light.vdb" "$OUT/oak128.push.light.vdb" && cmp "$OUT/oak128.shift.light.vdb" "$OUT/oak128.shift-split.light.vdb" &&
   cmp "$OUT/oak128.shift.light.vdb" "$OUT/oak128.pull.light.vdb"; then
  echo "light files of the four schemes: byte-identical" | tee -a "$OUT/lbsolve_oak128_wall.txt"
else
  echo "gpu.sh: FAILED: the schemes' light files differ" | tee -a "$OUT/lbsolve_oak128_wall.txt"; status=1
fi
rm -f "$OUT"/oak128.*.light.vdb
step bench_lbsolve_cpu.md "$BIN/bench_lbsolve" --device cpu --sizes 128 --solves-sizes 64 --iterations 16
exit $status
