#!/usr/bin/env python3
"""ncu_lines.py SOURCE.csv [N]: the hottest rows of an Nsight Compute source page export
(`ncu -i rep --page source --csv --print-source sass|cuda,sass`), by warp stall samples, with
each row's executed instructions; then the samples summed per CUDA source line where the export
has one (a "File Name" section per file, or a source-location column)."""
import csv, sys, collections

path = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 40
rows, header, fname = [], None, ""
with open(path, newline="", errors="replace") as f:
    for rec in csv.reader(f):
        if not rec:
            continue
        if rec[0] == "File Name":
            fname = rec[1] if len(rec) > 1 else ""
            header = None
            continue
        if header is None and ("Source" in rec or "Address" in rec or "# Address" in rec):
            header = rec
            print("columns:", header[:14])
            continue
        if header is None or len(rec) != len(header):
            continue
        rows.append((fname, dict(zip(header, rec))))

def col(name_part):
    for h in (header or []):
        if name_part in h:
            return h
    return None

def num(v):
    try:
        return float(str(v).replace(",", ""))
    except ValueError:
        return 0.0

stall = None
for _, r in rows[:1]:
    for h in r:
        if "Stall Sampling (All" in h or "Warp Stall Sampling" in h:
            stall = h
            break
execd = None
for _, r in rows[:1]:
    for h in r:
        if h.startswith("Instructions Executed") or h == "Warp Instructions Executed":
            execd = h
            break
print("rows", len(rows), "stall column", stall, "executed column", execd)
if not stall:
    sys.exit(0)
total = sum(num(r[stall]) for _, r in rows)
tot_exec = sum(num(r[execd]) for _, r in rows) if execd else 0
print("total stall samples", total, "executed", tot_exec)
src = "Source"
for fn, r in sorted(rows, key=lambda x: -num(x[1][stall]))[:n]:
    loc = r.get("# Address", r.get("Address", r.get("Line No", "")))
    print(f"{100*num(r[stall])/max(total,1):5.1f}%  exec {num(r.get(execd,0)):>12.0f}  {fn.split('/')[-1]}:{loc}  {r.get(src,'')[:110]}")
# per file (cuda view): samples per file
per = collections.Counter()
for fn, r in rows:
    per[fn.split('/')[-1]] += num(r[stall])
print("per file:", per.most_common(10))
# per opcode (sass view): samples and executed instructions
ops, opx = collections.Counter(), collections.Counter()
for fn, r in rows:
    text = r.get(src, "").strip()
    if not text:
        continue
    tok = text.split()
    op = tok[1] if tok[0].startswith("@") and len(tok) > 1 else tok[0]
    op = op.split(".")[0]
    ops[op] += num(r[stall])
    opx[op] += num(r.get(execd, 0))
if len(ops) > 1:
    print("per opcode (stall %, executed):")
    for op, v in ops.most_common(25):
        print(f"  {op:10s} {100*v/max(total,1):5.1f}%  {opx[op]:>14.0f}")
