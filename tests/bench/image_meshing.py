#!/usr/bin/env python3
"""Image-meshing quality on scikit-image's `camera` (512x512): the L2 error of
the piecewise-linear approximation on a uniform, a gradient-adapted, a
Hessian-adapted (isotropic) and three anisotropic (absolute Hessian
det^(-1/6)|H|, structure tensor, and the edge tensor: the gradient metric's
density with elements stretched along the structure tensor's coherent edges)
geodesic Delaunay meshes with the same vertex count; with `--flips`, each also after data-dependent edge flips;
with `--moves`, each also after vertex moves and flips (`geodex mesh --moves`).

Needs a venv with scikit-image and numpy (the image only) and a geodex binary:

    python3 -m venv /tmp/venv-meshing
    /tmp/venv-meshing/bin/pip install scikit-image numpy
    cargo build --release
    /tmp/venv-meshing/bin/python tests/bench/image_meshing.py \
        --geodex target/release/geodex --count 2000

Prints one JSON line per metric and a Markdown table. The image is scaled to
[0, 1]; the error is the root mean square over the 512^2 pixels.
"""

import argparse
import json
import os
import subprocess
import tempfile
import time

import numpy as np
from skimage import data


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--geodex", default="target/release/geodex")
    ap.add_argument("--count", type=int, default=2000)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--strength", type=float, default=8.0)
    ap.add_argument("--flips", action="store_true",
                    help="also run every metric with data-dependent edge flips (`geodex mesh --flips`)")
    ap.add_argument("--moves", action="store_true",
                    help="also run every metric with vertex moves and flips (`geodex mesh --moves`)")
    ap.add_argument("--metrics", default=None,
                    help="comma-separated subset of the metrics (default: all six)")
    args = ap.parse_args()
    image = data.camera().astype(np.float64) / 255.0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "camera.npy")
        np.save(path, image)
        # (metric, sigma, strength, extra flags): the isotropic ones with the
        # command-line settings, the anisotropic ones with the settings tuned
        # on this image (tests/bench/README.md; higher contrasts leave a
        # defect the Delaunay repair cannot fix).
        runs = [("uniform", args.sigma, args.strength, []),
                ("gradient", args.sigma, args.strength, []),
                ("hessian", args.sigma, args.strength, []),
                ("anisotropic-hessian", 1.0, 20.0, ["--anisotropy", "8"]),
                ("structure-tensor", 1.0, 32.0, ["--anisotropy", "4", "--rho", "1"]),
                # The gradient metric's density (same sigma and strength as
                # the isotropic rows), elements stretched along coherent edges.
                ("edge-tensor", args.sigma, args.strength, ["--anisotropy", "2", "--rho", "2"])]
        if args.metrics:
            keep = args.metrics.split(",")
            runs = [r for r in runs if r[0] in keep]
        variants = [[]] + ([["--flips"]] if args.flips else []) + ([["--moves"]] if args.moves else [])
        runs = [(m, s, k, e + v) for (m, s, k, e) in runs for v in variants]
        for metric, sigma, strength, extra in runs:
            metric_name = metric + (" + flips" if "--flips" in extra else "") + (
                " + moves" if "--moves" in extra else "")
            out = os.path.join(tmp, f"{metric}.ply")
            stats = os.path.join(tmp, f"{metric}.json")
            cmd = [args.geodex, "mesh", "--image", path, "--count", str(args.count),
                   "--metric", metric, "--sigma", str(sigma),
                   "--strength", str(strength), "--no-compare",
                   "--out", out, "--stats", stats] + extra
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            seconds = time.perf_counter() - t0
            with open(stats) as f:
                s = json.load(f)["stats"]
            row = {"metric": metric_name, "vertices": s["vertices"], "triangles": s["triangles"],
                   "added": s["added"], "l2_error": s["l2_error"], "seconds": seconds,
                   "flips": s.get("flips", 0), "moves": s.get("moves", 0)}
            print(json.dumps(row))
            rows.append(row)
    base = rows[0]["l2_error"]
    print()
    print("| metric | vertices | triangles | added by repair | L2 error | / uniform | seconds |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['metric']} | {r['vertices']} | {r['triangles']} | {r['added']} | "
              f"{r['l2_error']:.5f} | {r['l2_error'] / base:.3f} | {r['seconds']:.2f} |")


if __name__ == "__main__":
    main()
