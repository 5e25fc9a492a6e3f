#!/usr/bin/env python3
"""grove_e2e.py: the grove scene packs end to end from its meshes (CTest, needs canopy-voxelize).

  grove_e2e.py BIN_DIR GROVE.glb WORK_DIR

1. canopy-voxelize GROVE.glb --instances WORK/grove.scene.json  (the instance list only)
2. every model it names is voxelized from its glTF mesh (the model's "mesh" field):
   canopy-voxelize GROVE.glb --mesh M -o MODEL.density.vdb --resolution 48
3. canopy-octreepack --scene WORK/grove.scene.json -o WORK/grove.canopy; verify; info --json must
   list every model and instance of the scene.
Exits non-zero (with the failing command) on any problem.
"""
import json
import os
import subprocess
import sys


def run(cmd):
    print("+", " ".join(cmd), file=sys.stderr)
    r = subprocess.run(cmd, stdout=subprocess.PIPE)
    if r.returncode != 0:
        sys.exit(f"grove_e2e: command failed with exit code {r.returncode}: {' '.join(cmd)}")
    return r.stdout


def main():
    bin_dir, glb, work = sys.argv[1:4]
    os.makedirs(work, exist_ok=True)
    voxelize = os.path.join(bin_dir, "canopy-voxelize")
    pack = os.path.join(bin_dir, "canopy-octreepack")
    scene = os.path.join(work, "grove.scene.json")
    run([voxelize, glb, "--instances", scene, "--quiet"])
    with open(scene) as f:
        desc = json.load(f)
    for i, m in enumerate(desc["models"]):
        path = os.path.join(work, m["density"])
        run([voxelize, glb, "--mesh", str(m.get("mesh", i)), "-o", path, "--resolution", "48", "--quiet"])
    out = os.path.join(work, "grove.canopy")
    run([pack, "--scene", scene, "-o", out, "--ignore-light", "--quiet"])
    run([pack, "verify", out, "--quiet"])
    info = json.loads(run([pack, "info", out, "--json"]))
    if len(info["models"]) != len(desc["models"]) or info["instances"] != len(desc["instances"]):
        sys.exit(f"grove_e2e: packed {len(info['models'])} models / {info['instances']} instances, "
                 f"scene has {len(desc['models'])} / {len(desc['instances'])}")
    if any(m["bricks"] == 0 for m in info["models"]):
        sys.exit("grove_e2e: a model packed without any brick")
    print(f"grove_e2e: ok ({len(desc['models'])} models, {info['instances']} instances, "
          f"{info['file_bytes']} bytes, resident {100 * info['resident_fraction']:.2f}%)", file=sys.stderr)


if __name__ == "__main__":
    main()
