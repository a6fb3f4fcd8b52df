"""geodex's landmark distance rows (heat method) against potpourri3d computing
the same rows one call at a time, on the same icosphere and landmarks, in one run.

    cargo bench --bench shape_analysis --no-run
    BIN=$(ls -t target/release/deps/shape_analysis-* | grep -v '\\.d$' | head -1)
    python tests/bench/compare_distance_matrix.py $BIN 7 500

geodex: `shape_analysis matrix LEVEL COUNT heat PREFIX` builds the icosphere,
factors once, picks COUNT farthest-point landmarks and solves their rows in
parallel on every core (its own timing, setup included), and writes the mesh
and the landmarks for the peer. potpourri3d: one `MeshHeatMethodDistanceSolver`
(its robust Laplacian, the default) and one `compute_distance` per landmark,
as its users who need a matrix do today (it has no batch call). Error: mean
relative error against the great-circle distance over the vertices farther
than 0.1 from each landmark, over all rows, for both. potpourri3d is a peer,
not a dependency.
"""
import json
import os
import subprocess
import sys
import time

import numpy as np
import potpourri3d as pp3d


def sphere_error(V, sources, rows):
    u = V / np.linalg.norm(V, axis=1)[:, None]
    total, count = 0.0, 0
    for s, d in zip(sources, rows):
        a = u[s]
        exact = np.arctan2(np.linalg.norm(np.cross(a, u), axis=1), u @ a)
        m = exact > 0.1
        total += float(np.sum(np.abs(d[m] - exact[m]) / exact[m]))
        count += int(m.sum())
    return total / max(count, 1)


def main(binary, level, count):
    prefix = f"/tmp/geodex_matrix_ico{level}"
    line = subprocess.run([binary, "matrix", str(level), str(count), "heat", prefix],
                          check=True, capture_output=True, text=True).stdout.strip()
    g = json.loads(line.splitlines()[-1])
    print(json.dumps(g))

    V, F = pp3d.read_mesh(prefix + ".obj")
    landmarks = np.load(prefix + "_landmarks.npy")
    t = time.perf_counter()
    solver = pp3d.MeshHeatMethodDistanceSolver(V, F)
    setup = time.perf_counter() - t
    rows = []
    for s in landmarks:
        rows.append(solver.compute_distance(int(s)))
    total = time.perf_counter() - t
    err = sphere_error(V, landmarks, rows)
    print(json.dumps({"tool": "potpourri3d", "case": "matrix", "vertices": len(V), "landmarks": len(landmarks),
                      "setup_s": round(setup, 3), "total_s": round(total, 3), "mean_relative_error": round(err, 6),
                      "threads": int(os.environ.get("OMP_NUM_THREADS", "0")) or "default"}))
    print(json.dumps({"speedup": round(total / g["total_s"], 2),
                      "error_ratio_geodex_over_potpourri3d": round(g["mean_relative_error"] / err, 3)}))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
