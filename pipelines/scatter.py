#!/usr/bin/env python3
"""scatter.py: the forest scatter step. N instances of given plant models -> a scene JSON.

Writes a Canopy scene instance list (docs/scene-json.md) that canopy-octreepack --scene (and
canopy-lbsolve --scene) read. Each instance gets a model (uniformly, or by --weights), a position
on a disk (default) or square of the given radius/half-edge in the ground plane (y = 0, +Y up), a
random yaw about +Y and a uniform scale in [--scale-min, --scale-max]. With --min-spacing, a
candidate closer than that to an earlier instance is redrawn (up to 100 tries, then an error).

Deterministic: the same arguments give the same bytes (Python's Mersenne Twister with the given
seed; numbers printed with fixed precision). The output is written atomically.

  python3 pipelines/scatter.py -o forest.scene.json --count 400 --seed 1 --radius 60 \
      --model oak=oak_medium.density.vdb:oak_medium.light.chaar --model pine=pine_small.density.vdb

Exit codes follow Canopy's table: 0 ok, 1 usage, 2 I/O error.
"""
import argparse
import json
import math
import os
import random
import sys

from atomic_write import write_atomic


def parse_model(spec):
    """NAME=DENSITY.vdb[:LIGHT.chaar] -> dict."""
    if "=" not in spec:
        raise argparse.ArgumentTypeError(f"--model {spec!r}: expected NAME=DENSITY.vdb[:LIGHT.chaar]")
    name, paths = spec.split("=", 1)
    density, _, light = paths.partition(":")
    if not name or not density:
        raise argparse.ArgumentTypeError(f"--model {spec!r}: expected NAME=DENSITY.vdb[:LIGHT.chaar]")
    model = {"name": name, "density": density}
    if light:
        model["light"] = light
    return model


def scatter(models, count, seed, radius, square, scale_min, scale_max, min_spacing, weights):
    rng = random.Random(seed)
    cumulative, total = [], 0.0
    for w in weights:
        total += w
        cumulative.append(total)
    placed, instances = [], []
    for _ in range(count):
        for _attempt in range(100):
            if square:
                x, z = rng.uniform(-radius, radius), rng.uniform(-radius, radius)
            else:  # uniform on the disk
                r, theta = radius * math.sqrt(rng.random()), 2.0 * math.pi * rng.random()
                x, z = r * math.cos(theta), r * math.sin(theta)
            if min_spacing <= 0 or all((x - px) ** 2 + (z - pz) ** 2 >= min_spacing ** 2 for px, pz in placed):
                break
        else:
            raise RuntimeError(f"cannot place {count} instances {min_spacing} apart in radius {radius}")
        placed.append((x, z))
        pick = rng.random() * total
        model = next(i for i, c in enumerate(cumulative) if pick < c or i == len(cumulative) - 1)
        yaw = 2.0 * math.pi * rng.random()
        s = rng.uniform(scale_min, scale_max)
        c, n = s * math.cos(yaw), s * math.sin(yaw)
        # model -> world, row-major 4x4: scale, then yaw about +Y, then translate on the ground
        matrix = [c, 0.0, n, x, 0.0, s, 0.0, 0.0, -n, 0.0, c, z, 0.0, 0.0, 0.0, 1.0]
        instances.append({"model": model, "matrix": [round(v, 6) + 0.0 for v in matrix]})
    return instances


def main(argv):
    ap = argparse.ArgumentParser(description="Scatter plant instances into a Canopy scene JSON.")
    ap.add_argument("-o", "--output", required=True, help="output SCENE.json")
    ap.add_argument("--model", action="append", type=parse_model, required=True,
                    help="NAME=DENSITY.vdb[:LIGHT.chaar] (repeat for several models)")
    ap.add_argument("--weights", type=str, default="", help="comma-separated relative frequencies per model")
    ap.add_argument("--count", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--radius", type=float, default=50.0, help="disk radius (or square half-edge), metres")
    ap.add_argument("--square", action="store_true", help="scatter on a square instead of a disk")
    ap.add_argument("--scale-min", type=float, default=0.8)
    ap.add_argument("--scale-max", type=float, default=1.2)
    ap.add_argument("--min-spacing", type=float, default=0.0, help="minimum distance between instances, metres")
    try:
        a = ap.parse_args(argv)
    except SystemExit as e:
        return 0 if e.code == 0 else 1
    weights = [1.0] * len(a.model)
    if a.weights:
        try:
            weights = [float(w) for w in a.weights.split(",")]
        except ValueError:
            weights = []
        if len(weights) != len(a.model) or any(not math.isfinite(w) or w < 0 for w in weights) or sum(weights) <= 0:
            print("scatter.py: error: --weights needs one non-negative number per --model", file=sys.stderr)
            return 1
    if a.count < 1 or not (a.radius > 0) or not (0 < a.scale_min <= a.scale_max) or a.min_spacing < 0:
        print("scatter.py: error: need --count >= 1, --radius > 0, 0 < --scale-min <= --scale-max", file=sys.stderr)
        return 1
    try:
        instances = scatter(a.model, a.count, a.seed, a.radius, a.square, a.scale_min, a.scale_max,
                            a.min_spacing, weights)
    except RuntimeError as e:
        print(f"scatter.py: error: {e}", file=sys.stderr)
        return 1
    out_dir = os.path.dirname(os.path.abspath(a.output))
    models = []
    for m in a.model:  # paths relative to the JSON file, as docs/scene-json.md says
        rel = {k: (os.path.relpath(os.path.abspath(v), out_dir) if k != "name" else v) for k, v in m.items()}
        models.append(rel)
    # One model / instance per line: readable and diff-friendly.
    text = ('{\n "canopy_scene": 1,\n "models": [\n  '
            + ",\n  ".join(json.dumps(m) for m in models)
            + '\n ],\n "instances": [\n  '
            + ",\n  ".join(json.dumps(i) for i in instances)
            + "\n ]\n}\n")
    try:
        write_atomic(a.output, text)
    except OSError as e:
        print(f"scatter.py: error: {a.output}: {e.strerror}", file=sys.stderr)
        return 2
    print(f"scatter.py: {a.count} instances of {len(models)} models -> {a.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
