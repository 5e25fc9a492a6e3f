#!/usr/bin/env bash
# GPU checks and benchmark of canopy-haar, for the lead on the GPU host.
#   BIN=build/bin OUT=out/haar [LIGHT=plant.light.vdb] bash bench/haar/gpu.sh
# 1. test_haar_cuda: CUDA decode == CPU decode bit for bit (fp32 and fp16), 19 bases; on LIGHT
#    (a real lbsolve output) when given, else on a synthetic field.
# 2. bench_haar (CPU): size at 1% volume RMS vs dense fp32, the dissertation and ZFP; writes the
#    .chaar the GPU benchmark samples.
# 3. bench_haar_gpu: random trilinear lookups/s, compressed bricks vs a 3D texture and a plain array.
# 4. steps 2-3 again with fp16 coefficients.
# Logs: $OUT/test_haar_cuda.log, $OUT/bench_haar{,_fp16}.md, $OUT/bench_haar_gpu{,_fp16}.md.
set -euo pipefail
: "${BIN:?set BIN to the directory holding the built binaries}"
: "${OUT:?set OUT to a directory for the logs}"
mkdir -p "$OUT"
LIGHT=${LIGHT:-}
status=0

nvidia-smi -L > "$OUT/gpu.txt" 2>&1 || true

echo "== test_haar_cuda" >&2
CANOPY_HAAR_LIGHT_VDB="$LIGHT" "$BIN/test_haar_cuda" --gtest_color=no > "$OUT/test_haar_cuda.log" 2>&1 || status=1
if grep -q "SKIPPED" "$OUT/test_haar_cuda.log"; then echo "test_haar_cuda skipped: no GPU?" >&2; status=1; fi
tail -3 "$OUT/test_haar_cuda.log" >&2

echo "== bench_haar (CPU part)" >&2
if [[ -n "$LIGHT" ]]; then
  "$BIN/bench_haar" "$LIGHT" --write-chaar "$OUT/bench.chaar" > "$OUT/bench_haar.md" || status=1
else
  "$BIN/bench_haar" --synthetic 128 --write-chaar "$OUT/bench.chaar" > "$OUT/bench_haar.md" || status=1
fi
tail -8 "$OUT/bench_haar.md" >&2

echo "== bench_haar_gpu" >&2
"$BIN/bench_haar_gpu" "$OUT/bench.chaar" > "$OUT/bench_haar_gpu.md" || status=1
cat "$OUT/bench_haar_gpu.md" >&2

# The same with fp16 coefficients (half the coefficient bytes; a different size/speed trade-off).
echo "== fp16 coefficients" >&2
if [[ -n "$LIGHT" ]]; then
  "$BIN/bench_haar" "$LIGHT" --precision fp16 --write-chaar "$OUT/bench16.chaar" > "$OUT/bench_haar_fp16.md" || status=1
else
  "$BIN/bench_haar" --synthetic 128 --precision fp16 --write-chaar "$OUT/bench16.chaar" > "$OUT/bench_haar_fp16.md" || status=1
fi
tail -8 "$OUT/bench_haar_fp16.md" >&2
"$BIN/bench_haar_gpu" "$OUT/bench16.chaar" > "$OUT/bench_haar_gpu_fp16.md" || status=1
tail -4 "$OUT/bench_haar_gpu_fp16.md" >&2
exit $status
