#!/bin/sh
# Runs the lbsolve checks that need a GPU: the CUDA-vs-CPU test and the benchmark (CUDA, then the
# CPU figure on the same host). Exits non-zero if a step fails or the CUDA tests were skipped.
# Usage: BIN=build/bin OUT=/some/log/dir sh bench/lbsolve/gpu.sh
set -u
: "${BIN:?set BIN to the directory holding the built binaries (build/bin)}"
: "${OUT:?set OUT to a directory for the logs}"
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
step bench_lbsolve_cuda.md "$BIN/bench_lbsolve" --device cuda --sizes 128,256 --solves-sizes 128,256 --iterations 200
step bench_lbsolve_cpu.md "$BIN/bench_lbsolve" --device cpu --sizes 128 --solves-sizes 64 --iterations 16
exit $status
