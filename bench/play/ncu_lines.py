#!/usr/bin/env python3
"""ncu_lines.py SOURCE.csv [N]: the hottest CUDA source lines of an Nsight Compute source page
export (`ncu -i rep --page source --csv --print-source cuda,sass`, kernel built with -lineinfo), by
warp stall samples, with each line's executed warp instructions, threads per instruction and
local-memory L2 sectors; then the samples and instructions per SASS opcode.

The export has a "File Path" (older: "File Name") record per source file, a header row with "Line
No", then one row per CUDA line (Line No set: the totals of its SASS) followed by that line's SASS
rows (Line No empty, the instruction in the second "Source" column)."""
import collections
import csv
import sys

path = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 40


def num(v):
    try:
        return float(str(v).replace(",", ""))
    except ValueError:
        return 0.0


lines, ops, opx = {}, collections.Counter(), collections.Counter()
fname, header = "", None
total = [0.0, 0.0, 0.0]
with open(path, newline="", errors="replace") as f:
    for rec in csv.reader(f):
        if not rec:
            continue
        if rec[0] in ("File Path", "File Name"):
            fname, header = (rec[1].split("/")[-1] if len(rec) > 1 else ""), None
            continue
        if header is None:
            if "Line No" in rec:
                header = rec
                col = {h: i for i, h in reversed(list(enumerate(rec)))}  # first occurrence of each name
                stall, execd = col["Warp Stall Sampling (All Samples)"], col["Instructions Executed"]
                threads = col.get("Thread Instructions Executed")
                local = col.get("L2 Theoretical Sectors Local")
                sass = max(i for i, h in enumerate(rec) if h == "Source")  # the second "Source": SASS text
            continue
        if len(rec) != len(header):
            continue
        if rec[0]:  # a CUDA source line: its SASS rows' totals
            st, ex = num(rec[stall]), num(rec[execd])
            th = num(rec[threads]) if threads is not None else 0.0
            lines[(fname, int(num(rec[0])))] = (st, ex, th, num(rec[local]) if local is not None else 0.0, rec[1].strip()[:90])
            total[0] += st
            total[1] += ex
            total[2] += th
        else:  # a SASS row
            text = rec[sass].strip()
            if not text or text == "...":
                continue
            tok = text.split()
            op = (tok[1] if tok[0].startswith("@") and len(tok) > 1 else tok[0]).split(".")[0]
            ops[op] += num(rec[stall])
            opx[op] += num(rec[execd])
if header is None:
    sys.exit(f"{path}: no 'Line No' header (export with --print-source cuda,sass from a -lineinfo build)")
print(f"stall samples {total[0]:.0f}, warp instructions executed {total[1] / 1e9:.2f} G, "
      f"{total[2] / max(total[1], 1):.1f} threads per instruction")
print(" stall%  instr G  thr/instr  local L2 sectors M  file:line  source")
for (fn, ln), (st, ex, th, lo, src) in sorted(lines.items(), key=lambda kv: -kv[1][0])[:n]:
    print(f"{100 * st / max(total[0], 1):6.1f}%  {ex / 1e9:6.2f}  {th / max(ex, 1):8.1f}  {lo / 1e6:10.1f}  {fn}:{ln}  {src}")
if ops:
    print("per opcode (stall %, executed):")
    for op, v in ops.most_common(25):
        print(f"  {op:10s} {100 * v / max(total[0], 1):5.1f}%  {opx[op]:>14.0f}")
