#!/usr/bin/env python3
"""scene_models.py: helpers for Makefile scene builds (pipelines/build.mk).

  scene_models.py SCENE.json --light-suffix .light.chaar --makefile OUT.mk
      writes SCENE_DENSITIES := ... and SCENE_LIGHTS := ... (the models' files) for make
  scene_models.py SCENE.json --light-suffix .light.chaar --write-json OUT.json
      writes the scene list with each model's "light" set to its density path with
      ".density.vdb" replaced by the suffix (docs/scene-json.md)

Outputs are written atomically (temporary file + rename). Exit codes: 0 ok, 1 usage, 2 I/O,
3 invalid input.
"""
import argparse
import json
import os
import sys

from atomic_write import write_atomic


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--light-suffix", default=".light.chaar")
    ap.add_argument("--makefile")
    ap.add_argument("--write-json")
    a = ap.parse_args()
    try:
        with open(a.scene) as f:
            scene = json.load(f)
    except OSError as e:
        print(f"scene_models.py: error: {a.scene}: {e.strerror}", file=sys.stderr)
        return 2
    except ValueError as e:
        print(f"scene_models.py: error: {a.scene}: not JSON ({e})", file=sys.stderr)
        return 3
    models = scene.get("models")
    if not isinstance(models, list) or not all(isinstance(m, dict) and "density" in m for m in models):
        print(f"scene_models.py: error: {a.scene}: no models with density paths", file=sys.stderr)
        return 3
    for m in models:
        d = m["density"]
        stem = d[: -len(".density.vdb")] if d.endswith(".density.vdb") else os.path.splitext(d)[0]
        m["light"] = stem + a.light_suffix
    if a.makefile:
        write_atomic(a.makefile,
                     "SCENE_DENSITIES := " + " ".join(m["density"] for m in models) + "\n" +
                     "SCENE_LIGHTS := " + " ".join(m["light"] for m in models) + "\n")
    if a.write_json:
        write_atomic(a.write_json, json.dumps(scene, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
