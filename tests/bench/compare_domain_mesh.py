#!/usr/bin/env python3
"""Domain meshing side by side with Shewchuk's Triangle (PyPI `triangle`,
quality flag `q25` plus an area bound searched so that it reaches the same
vertex count) on a disc, an L-shape and a square with two holes.

Needs a venv with `triangle` and numpy, and a geodex binary:

    python3 -m venv /tmp/venv-triangle
    /tmp/venv-triangle/bin/pip install triangle numpy
    cargo build --release
    /tmp/venv-triangle/bin/python tests/bench/compare_domain_mesh.py \
        --geodex target/release/geodex --counts 2000,20000

geodex's time is the operation's own (`stats.seconds`: meshing, without
process start and file writing); Triangle's is the `triangulate` call of its
final area bound (the search for that bound is not timed), best of
`--repeat`. Both see the same polygons. Prints one JSON line per run and a
Markdown table: vertices, share of triangles whose smallest angle is at
least 25/30/35/40 degrees, the mean and minimum smallest angle, seconds.
"""

import argparse
import json
import math
import os
import subprocess
import tempfile
import time

import numpy as np
import triangle


def disc(c, r, n):
    return [[c[0] + r * math.cos(2 * math.pi * k / n), c[1] + r * math.sin(2 * math.pi * k / n)]
            for k in range(n)]


DOMAINS = {
    "disc": ([disc([50, 50], 50, 256)], []),
    "L-shape": ([[[0, 0], [100, 0], [100, 40], [40, 40], [40, 100], [0, 100]]], []),
    "square, two holes": (
        [[[0, 0], [100, 0], [100, 100], [0, 100]],
         [[20, 20], [20, 45], [45, 45], [45, 20]],
         disc([70, 65], 15, 48)],
        [[32.5, 32.5], [70, 65]],
    ),
}


def min_angles(v, t):
    p = v[t]  # (nt, 3, 2)
    out = np.full(len(t), 180.0)
    for k in range(3):
        a, b, c = p[:, k], p[:, (k + 1) % 3], p[:, (k + 2) % 3]
        u, w = b - a, c - a
        cross = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
        dot = (u * w).sum(axis=1)
        out = np.minimum(out, np.degrees(np.arctan2(cross, dot)))
    return out


def summary(name, tool, nv, angles, seconds):
    row = {"domain": name, "tool": tool, "vertices": int(nv), "triangles": len(angles),
           "ge25": float((angles >= 25).mean()), "ge30": float((angles >= 30).mean()),
           "ge35": float((angles >= 35).mean()), "ge40": float((angles >= 40).mean()),
           "mean": float(angles.mean()), "min": float(angles.min()), "seconds": seconds}
    print(json.dumps(row), flush=True)
    return row


def run_triangle(rings, holes, count, repeat):
    vertices, segments = [], []
    for ring in rings:
        base = len(vertices)
        vertices += ring
        segments += [[base + k, base + (k + 1) % len(ring)] for k in range(len(ring))]
    pslg = {"vertices": np.array(vertices, float), "segments": np.array(segments)}
    if holes:
        pslg["holes"] = np.array(holes, float)
    area = abs(sum(x0 * y1 - x1 * y0 for ring in rings[:1]
                   for (x0, y0), (x1, y1) in zip(ring, ring[1:] + ring[:1]))) / 2
    # Search the area bound a (in log space) so that the mesh has ~count vertices.
    lo, hi = math.log(area / count / 20), math.log(area / count * 20)
    best = None
    for _ in range(40):
        mid = (lo + hi) / 2
        m = triangle.triangulate(pslg, f"pq25a{math.exp(mid):.6f}")
        n = len(m["vertices"])
        if best is None or abs(n - count) < abs(best[1] - count):
            best = (mid, n)
        if abs(n - count) <= 0.01 * count:
            break
        if n > count:
            lo = mid
        else:
            hi = mid
    flags = f"pq25a{math.exp(best[0]):.6f}"
    seconds = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        m = triangle.triangulate(pslg, flags)
        seconds = min(seconds, time.perf_counter() - t0)
    return len(m["vertices"]), min_angles(m["vertices"], m["triangles"]), seconds


def run_geodex(binary, rings, count, repeat, tmp):
    # GeoJSON [x, y] = [column, row]: the bench's (x, y) go in as they are.
    geometry = {"type": "Polygon", "coordinates": [ring + ring[:1] for ring in rings]}
    path = os.path.join(tmp, "domain.geojson")
    with open(path, "w") as f:
        json.dump(geometry, f)
    out, stats = os.path.join(tmp, "mesh.json"), os.path.join(tmp, "stats.json")
    seconds = float("inf")
    for _ in range(repeat):
        subprocess.run([binary, "mesh-domain", "--polygons", path, "--count", str(count),
                        "--out", out, "--stats", stats], check=True, stdout=subprocess.DEVNULL)
        with open(stats) as f:
            s = json.load(f)["stats"]
        seconds = min(seconds, s["seconds"])
    with open(out) as f:
        m = json.load(f)
    v = np.array(m["vertices"], float)[:, :2]
    t = np.array(m["faces"], int)
    return len(v), min_angles(v, t), seconds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--geodex", default="target/release/geodex")
    ap.add_argument("--counts", default="2000,20000")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for count in [int(c) for c in args.counts.split(",")]:
            for name, (rings, holes) in DOMAINS.items():
                nv, a, s = run_geodex(args.geodex, rings, count, args.repeat, tmp)
                rows.append(summary(name, "geodex", nv, a, s))
                nv, a, s = run_triangle(rings, holes, count, args.repeat)
                rows.append(summary(name, "triangle q25", nv, a, s))
    print()
    print("| domain | tool | vertices | >= 25° | >= 30° | >= 35° | >= 40° | mean | min | seconds |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['domain']} | {r['tool']} | {r['vertices']} | {100 * r['ge25']:.1f} % "
              f"| {100 * r['ge30']:.1f} % | {100 * r['ge35']:.1f} % | {100 * r['ge40']:.1f} % "
              f"| {r['mean']:.1f}° | {r['min']:.1f}° | {r['seconds']:.4f} |")


if __name__ == "__main__":
    main()
