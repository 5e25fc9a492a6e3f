#!/usr/bin/env bash
# gpu-lbsolve-ncu.sh: Nsight Compute on the dense pull update (issue 3; bench/lbsolve/NOTES.md,
# fifth round): the DRAM bytes one launch moves per node update, against the 156 B of the model,
# and how busy DRAM and the SMs are, at 128^3 and 256^3 on the synthetic plant.
#   Here: ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/bench_lbsolve -- ../shared
#   There: bash bench/gpu-lbsolve-ncu.sh  (.gpu carried)
set -u
source "$(dirname "$0")/gpu-common.sh"
NCU=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
[[ -n $NCU ]] || { echo "no ncu on this host"; exit 1; }
for n in ${SIZES:-128 256}; do
  step "pull $n^3"
  timeout 250 "$NCU" --kernel-name regex:pullLeafKernel --launch-skip 50 --launch-count 1 \
    --section SpeedOfLight --section MemoryWorkloadAnalysis --section Occupancy --section LaunchStats \
    --metrics dram__bytes_read.sum,dram__bytes_write.sum,lts__t_bytes.sum,l1tex__t_bytes.sum,gpu__time_duration.sum \
    bench_lbsolve --device cuda --sizes "$n" --fill plant --schemes pull --in-flight 1 --iterations 100 --solves-sizes "" \
    > "$O/ncu-pull-$n.txt" 2>&1 || { echo "ncu failed"; status=1; }
  grep -E "dram__bytes|lts__t_bytes|l1tex__t_bytes|gpu__time_duration|DRAM Throughput|Memory Throughput|Compute \(SM\)|Achieved Occupancy|Registers Per|Grid Size|Block Size" "$O/ncu-pull-$n.txt" | head -20
  python3 - "$O/ncu-pull-$n.txt" "$n" <<'PY'
import re, sys
text = open(sys.argv[1]).read(); n = int(sys.argv[2])
def metric(name):
    m = re.search(name + r"\s+(\S+)\s+([\d,\.]+)", text)
    if not m: return None
    unit, v = m.group(1), float(m.group(2).replace(",", ""))
    scale = {"byte": 1, "Kbyte": 1e3, "Mbyte": 1e6, "Gbyte": 1e9, "KB": 1e3, "MB": 1e6, "GB": 1e9}.get(unit, 1)
    return v * scale
r, w = metric("dram__bytes_read.sum"), metric("dram__bytes_write.sum")
t = metric("gpu__time_duration.sum")
for label, nodes in (("lattice node", n ** 3), ("interior node", (n - 2) ** 3)):
    if r is not None and w is not None:
        print(f"pull {n}^3: DRAM read {r/nodes:.1f} B + write {w/nodes:.1f} B = {(r+w)/nodes:.1f} B per {label} (model: 80 + 76 = 156)")
if r is not None and w is not None and t:
    print(f"pull {n}^3: launch {t} (ncu units), DRAM bytes {(r+w)/1e6:.1f} MB")
PY
done
date -u
exit $status
