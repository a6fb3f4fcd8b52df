"""potpourri3d (geometry-central, heat method and fast marching) on the same
icospheres as `cargo bench --bench mesh_geodesics`.

    cargo bench --bench mesh_geodesics -- dump 7 /tmp/ico7.obj
    OMP_NUM_THREADS=1 python tests/bench/compare_potpourri3d.py /tmp/ico7.obj

Prints one JSON line per method: factorisation and per-query time (heat),
fast marching time, mean relative and max absolute error against the
great-circle distance from vertex 0. potpourri3d is a peer, not a dependency.
"""
import json
import sys
import time

import numpy as np
import potpourri3d as pp3d


def errors(V, d):
    if not np.allclose(np.linalg.norm(V, axis=1), 1.0, atol=1e-6):
        return float("nan"), float("nan")  # not a unit sphere: no closed form
    p0 = V[0] / np.linalg.norm(V[0])
    u = V / np.linalg.norm(V, axis=1)[:, None]
    exact = np.arctan2(np.linalg.norm(np.cross(p0, u), axis=1), u @ p0)
    m = exact > 0.1
    return float(np.mean(np.abs(d[m] - exact[m]) / exact[m])), float(np.max(np.abs(d - exact)))


def main(path):
    V, F = pp3d.read_mesh(path)
    n = len(V)
    t = time.perf_counter()
    solver = pp3d.MeshHeatMethodDistanceSolver(V, F)
    d = solver.compute_distance(0)  # construction + first query: factorisations included
    first = time.perf_counter() - t
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        d = solver.compute_distance(0)
        best = min(best, time.perf_counter() - t)
    mean, mx = errors(V, d)
    print(json.dumps({"peer": "potpourri3d", "case": "heat", "vertices": n, "factor_s": round(first - best, 4),
                      "query_s": round(best, 4), "mean_rel_err": mean, "max_abs_err": mx}))
    if hasattr(pp3d, "compute_distance_fast_marching") or hasattr(pp3d, "MeshFastMarchingDistanceSolver"):
        best = float("inf")
        for _ in range(3):
            t = time.perf_counter()
            if hasattr(pp3d, "MeshFastMarchingDistanceSolver"):
                s = pp3d.MeshFastMarchingDistanceSolver(V, F)
                d = s.compute_distance([[(0, [])]])
            else:
                d = pp3d.compute_distance_fast_marching(V, F, [0])
            best = min(best, time.perf_counter() - t)
        mean, mx = errors(V, np.asarray(d))
        print(json.dumps({"peer": "potpourri3d", "case": "fmm", "vertices": n, "solve_s": round(best, 4),
                          "mean_rel_err": mean, "max_abs_err": mx}))


if __name__ == "__main__":
    main(sys.argv[1])
