#!/usr/bin/env bash
# gpu-lbsolve-gaps.sh: is the dense pull update at 128^3 slower per node than at 256^3 inside the
# kernel, or between kernels? (issue 3; bench/lbsolve/NOTES.md, sixth round). One pull launch's
# duration under Nsight Compute with the clocks and caches left alone (--clock-control none
# --cache-control none), against the time per iteration the benchmark measures; and, where nsys
# exists, the kernel durations and gaps of a whole solve.
#   Here: ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/bench_lbsolve -- ../shared
#   There: bash bench/gpu-lbsolve-gaps.sh  (.gpu carried)
set -u
source "$(dirname "$0")/gpu-common.sh"
NCU=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
NSYS=$(command -v nsys || ls /usr/local/cuda/bin/nsys 2>/dev/null || ls -d /opt/nvidia/nsight-systems*/bin/nsys 2>/dev/null | head -1 || true)
for n in ${SIZES:-128 256}; do
  step "bench $n^3"
  bench_lbsolve --device cuda --sizes "$n" --fill plant --schemes pull --in-flight 1 --iterations 400 --solves-sizes "" 2>&1 | grep -E "copy|^\| plant"
  if [[ -n $NCU ]]; then
    step "ncu $n^3 (clocks and caches as they are)"
    timeout 200 "$NCU" --kernel-name regex:pullLeafKernel --launch-skip 50 --launch-count 5 --clock-control none --cache-control none \
      --metrics gpu__time_duration.sum,dram__bytes_read.sum,dram__bytes_write.sum,sm__cycles_active.avg,sm__cycles_active.max,gpc__cycles_elapsed.max \
      bench_lbsolve --device cuda --sizes "$n" --fill plant --schemes pull --in-flight 1 --iterations 100 --solves-sizes "" \
      > "$O/ncu-gaps-$n.txt" 2>&1 || echo "ncu failed"
    grep -E "gpu__time_duration|dram__bytes|sm__cycles_active|gpc__cycles" "$O/ncu-gaps-$n.txt" | head -30
  fi
  if [[ -n $NSYS ]]; then
    step "nsys $n^3"
    timeout 200 "$NSYS" profile -o "$O/nsys-$n" --force-overwrite true -t cuda \
      bench_lbsolve --device cuda --sizes "$n" --fill plant --schemes pull --in-flight 1 --iterations 400 --solves-sizes "" > /dev/null 2>&1 || echo "nsys failed"
    "$NSYS" stats -r cuda_gpu_kern_sum -f csv -o "$O/nsys-$n" "$O/nsys-$n.nsys-rep" > /dev/null 2>&1
    "$NSYS" stats -r cuda_gpu_trace -f csv -o "$O/nsys-$n" "$O/nsys-$n.nsys-rep" > /dev/null 2>&1
    head -5 "$O/nsys-${n}_cuda_gpu_kern_sum.csv" 2>/dev/null
    python3 - "$O/nsys-${n}_cuda_gpu_trace.csv" <<'PY'
import csv, sys, statistics
try:
    rows = list(csv.DictReader(open(sys.argv[1])))
except Exception as e:
    print("no trace:", e); sys.exit(0)
k = [r for r in rows if "pullLeafKernel" in r.get("Name", "")]
if not k: print("no pull launches in the trace"); sys.exit(0)
start = [int(r["Start (ns)"]) for r in k]; dur = [int(r["Duration (ns)"]) for r in k]
gaps = [start[i + 1] - (start[i] + dur[i]) for i in range(len(k) - 1)]
period = [start[i + 1] - start[i] for i in range(len(k) - 1)]
print(f"pull launches {len(k)}: duration median {statistics.median(dur)/1e3:.1f} us, start-to-start median {statistics.median(period)/1e3:.1f} us, gap median {statistics.median(gaps)/1e3:.2f} us (min {min(gaps)/1e3:.2f}, max {max(gaps)/1e3:.2f})")
PY
    rm -f "$O"/nsys-$n.nsys-rep "$O"/nsys-$n.sqlite "$O"/nsys-${n}_cuda_gpu_trace.csv
  fi
done
date -u
exit $status
