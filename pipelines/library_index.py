#!/usr/bin/env python3
"""library_index.py: the index of a built plant library (pipelines/build.mk `library`).

  library_index.py -o library.json [--octreepack canopy-octreepack] PLANT.canopy...

For each packed plant, in the order given: its name, file (relative to the index), size, SHA-256
and the summary `canopy-octreepack info --json` reports (models, levels, nodes, bricks, pages,
section bytes). The index holds no timestamps or absolute paths, so the same files give the same
bytes. Every file is checked with `canopy-octreepack verify` first; a bad one fails the index.
Written atomically (temporary file + rename). Exit codes: 0 ok, 1 usage, 2 I/O, 3 invalid input.
"""
import argparse
import hashlib
import json
import os
import subprocess
import sys

from atomic_write import write_atomic


def fail(code, msg):
    print(f"library_index.py: error: {msg}", file=sys.stderr)
    sys.exit(code)


def sha256(path):
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as e:
        fail(2, f"{path}: {e.strerror}")
    return h.hexdigest()


def octreepack(tool, *args):
    try:
        r = subprocess.run([tool, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    except OSError as e:
        fail(2, f"{tool}: cannot run ({e.strerror})")
    return r.returncode, r.stdout, r.stderr.strip()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--octreepack", default="canopy-octreepack")
    ap.add_argument("files", nargs="*")
    a = ap.parse_args()
    base = os.path.dirname(os.path.abspath(a.output))
    plants = []
    for path in a.files:
        if not os.path.isfile(path):
            fail(2, f"{path}: no such file")
        rc, _, err = octreepack(a.octreepack, "verify", "--quiet", path)
        if rc != 0:
            fail(3, f"{path}: does not verify ({err.splitlines()[-1] if err else f'exit {rc}'})")
        rc, out, err = octreepack(a.octreepack, "info", "--json", "--quiet", path)
        if rc != 0:
            fail(3, f"{path}: info failed ({err.splitlines()[-1] if err else f'exit {rc}'})")
        try:
            info = json.loads(out)
        except ValueError as e:
            fail(3, f"{path}: canopy-octreepack info printed no JSON ({e})")
        name = os.path.basename(path)
        if name.endswith(".canopy"):
            name = name[: -len(".canopy")]
        info.pop("file", None)  # absolute or build-relative: not part of a reproducible index
        plants.append({
            "name": name,
            "file": os.path.relpath(os.path.abspath(path), base),
            "bytes": os.path.getsize(path),
            "sha256": sha256(path),
            "info": info,
        })
    index = {"canopy_library": 1, "plants": plants}
    try:
        write_atomic(a.output, json.dumps(index, indent=1, sort_keys=True) + "\n")
    except OSError as e:
        fail(2, f"{a.output}: {e.strerror}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
