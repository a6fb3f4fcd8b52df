#!/usr/bin/env python3
"""Where geodex's exact distance and pygeodesic's disagree, which one is right?

Runs `geodex mesh-distance --method exact` and pygeodesic's
`PyGeodesicAlgorithmExact.geodesicDistances` (the whole map) from one source
vertex, lists the vertices where they differ by more than --tol (relative),
and for each of the worst --check of them asks pygeodesic for its own
single-pair path (`geodesicDistance(source, v)`): the length of that polyline
is an upper bound on the true distance. A map value above a real path's
length is wrong; a map value equal to it is that path's length.

    /tmp/venv-mesh/bin/python tests/bench/check_exact_disagreements.py \
        --bin target/release/geodex /tmp/slivers6.obj

The venv needs numpy, potpourri3d (to read the mesh as pygeodesic is fed
elsewhere in these benchmarks) and pygeodesic.
"""

import argparse
import os
import subprocess
import tempfile

import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/geodex")
    ap.add_argument("--source", type=int, default=0)
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--check", type=int, default=5)
    ap.add_argument("mesh")
    a = ap.parse_args()

    import potpourri3d as pp3d
    import pygeodesic.geodesic as geodesic

    with tempfile.TemporaryDirectory() as work:
        out = os.path.join(work, "d.npy")
        subprocess.run(
            [a.bin, "mesh-distance", "--mesh", a.mesh, "--method", "exact",
             "--source-vertex", str(a.source), "--out", out],
            check=True, capture_output=True,
        )
        ours = np.load(out)
    V, F = pp3d.read_mesh(a.mesh)
    alg = geodesic.PyGeodesicAlgorithmExact(V, F)
    theirs, _ = alg.geodesicDistances(np.array([a.source]), None)
    m = ours > 0
    rel = np.zeros_like(ours)
    rel[m] = (theirs[m] - ours[m]) / ours[m]
    print(f"{a.mesh}: {len(ours)} vertices; pygeodesic map minus geodex, relative: "
          f"min {rel.min():.3e}, max {rel.max():.3e}")
    print(f"  pygeodesic larger by > {a.tol:g}: {int((rel > a.tol).sum())} vertices; "
          f"smaller: {int((rel < -a.tol).sum())}")
    worst = np.argsort(-np.abs(rel))[: a.check]
    for v in worst:
        if abs(rel[v]) <= a.tol:
            break
        _, path = alg.geodesicDistance(a.source, int(v))
        path = np.asarray(path)
        length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
        print(f"  vertex {v}: geodex {ours[v]:.15g}, pygeodesic map {theirs[v]:.15g}, "
              f"pygeodesic's own path to it {length:.15g} ({len(path)} points)")


if __name__ == "__main__":
    main()
