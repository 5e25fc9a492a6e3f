#!/usr/bin/env python3
"""grove_e2e.py: the grove scene packs end to end from its meshes (CTest, needs canopy-voxelize).

  grove_e2e.py BIN_DIR GROVE.glb WORK_DIR

In WORK_DIR (relative paths, so that both routes below name the same files):
1. canopy-voxelize GROVE.glb --instances grove.scene.json  (the instance list only)
2. every model it names is voxelised from its glTF mesh (the model's "mesh" field):
   canopy-voxelize GROVE.glb --mesh M -o grove.meshM.density.vdb --resolution 32
3. the JSON route: canopy-octreepack --scene grove.scene.json -o grove.canopy; verify; info --json
   must list every model and instance of the scene.
4. the glTF route: canopy-octreepack --scene GROVE.glb <the lattices, shuffled> -o grove_glb.canopy
   must give the same bytes as the JSON route.
5. lattices that do not fit the scene (one missing, one mesh twice, a lattice of another glTF, a
   lattice of the whole scene) fail with exit 3, one line on stderr, and no output left behind.
Exits non-zero (with the failing command) on any problem.
"""
import json
import os
import subprocess
import sys


def run(cmd, expect=0):
    print("+", " ".join(cmd), file=sys.stderr)
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != expect:
        sys.exit(f"grove_e2e: exit code {r.returncode}, expected {expect}: {' '.join(cmd)}\n{r.stderr}")
    return r


def main():
    bin_dir, glb, work = sys.argv[1:4]
    glb = os.path.abspath(glb)
    os.makedirs(work, exist_ok=True)
    os.chdir(work)
    voxelize = os.path.join(bin_dir, "canopy-voxelize")
    pack = os.path.join(bin_dir, "canopy-octreepack")
    scene = "grove.scene.json"
    run([voxelize, glb, "--instances", scene, "--quiet"])
    with open(scene) as f:
        desc = json.load(f)
    lattices = []
    for i, m in enumerate(desc["models"]):
        lattices.append(m["density"])
        run([voxelize, glb, "--mesh", str(m.get("mesh", i)), "-o", m["density"], "--resolution", "32", "--quiet"])

    # The JSON route.
    out = "grove.canopy"
    run([pack, "--scene", scene, "-o", out, "--ignore-light", "--quiet"])
    run([pack, "verify", out, "--quiet"])
    info = json.loads(run([pack, "info", out, "--json"]).stdout)
    if len(info["models"]) != len(desc["models"]) or info["instances"] != len(desc["instances"]):
        sys.exit(f"grove_e2e: packed {len(info['models'])} models / {info['instances']} instances, "
                 f"scene has {len(desc['models'])} / {len(desc['instances'])}")
    if any(m["bricks"] == 0 for m in info["models"]):
        sys.exit("grove_e2e: a model packed without any brick")

    # The glTF route: same models, instances and bytes, whatever the order of the lattices.
    out_glb = "grove_glb.canopy"
    run([pack, "--scene", glb] + lattices[::-1] + ["-o", out_glb, "--quiet"])
    with open(out, "rb") as a, open(out_glb, "rb") as b:
        if a.read() != b.read():
            sys.exit(f"grove_e2e: {out_glb} (--scene {glb}) differs from {out} (--scene {scene})")

    # Lattices that do not fit the scene.
    run([voxelize, "--write-sample", "sample.glb", "--quiet"])
    run([voxelize, "sample.glb", "--mesh", "0", "-o", "other.density.vdb", "--resolution", "16", "--quiet"])
    run([voxelize, glb, "-o", "whole.density.vdb", "--resolution", "16", "--quiet"])
    bad = "bad.canopy"
    cases = {
        "missing": lattices[:-1],
        "twice": lattices + [lattices[0]],
        "other glTF": lattices + ["other.density.vdb"],
        "whole scene": lattices + ["whole.density.vdb"],
    }
    for what, inputs in cases.items():
        r = run([pack, "--scene", glb] + inputs + ["-o", bad], expect=3)
        lines = r.stderr.strip().splitlines()
        if len(lines) != 1 or os.path.exists(bad):
            sys.exit(f"grove_e2e: {what}: expected one error line and no {bad}, got {r.stderr!r}")
        print(f"grove_e2e: {what}: {lines[0]}", file=sys.stderr)
    print(f"grove_e2e: ok ({len(desc['models'])} models, {info['instances']} instances, "
          f"{info['file_bytes']} bytes, resident {100 * info['resident_fraction']:.2f}%, "
          f"glb and JSON routes identical)", file=sys.stderr)


if __name__ == "__main__":
    main()
