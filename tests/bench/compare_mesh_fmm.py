"""Fast marching and the heat method on meshes, end to end against
potpourri3d in memory, with errors against the exact polyhedral distance.

geodex runs through its CLI (process start, read, weld, topology, solve,
write an NPY), best of `--repeat`; potpourri3d is timed in memory
(`read_mesh`, then `MeshFastMarchingDistanceSolver(V, F).compute_distance`,
or `MeshHeatMethodDistanceSolver(V, F, use_robust=True).compute_distance`),
best of `--repeat`. Errors: mean relative error from vertex 0 against
geodex's exact method, over vertices farther than 5 % of the largest
distance (as `compare_robust_heat.py`).

    /tmp/venv-mesh/bin/python tests/bench/compare_exact_files.py --decimate /tmp/scanned/dragon.ply 6000 /tmp/dragon3k.obj
    OMP_NUM_THREADS=1 /tmp/venv-mesh/bin/python tests/bench/compare_mesh_fmm.py \
        --bin target/release/geodex /tmp/dragon3k.obj /tmp/slivers6.obj /tmp/ico6.obj /tmp/dragon50k.obj

One JSON line per mesh.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_robust_heat import err, geodex  # noqa: E402


def best_of(k, f):
    best, out = float("inf"), None
    for _ in range(k):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return out, best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/geodex")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("meshes", nargs="+")
    a = ap.parse_args()
    import potpourri3d as pp3d
    for mesh in a.meshes:
        ref, _, _ = geodex(a.bin, mesh, "exact")
        row = {"mesh": os.path.basename(mesh), "vertices": len(ref)}
        for method in ["fast_marching", "heat"]:
            runs = [geodex(a.bin, mesh, method) for _ in range(a.repeat)]
            row[f"geodex_{method}_s"] = round(min(r[1] for r in runs), 4)
            row[f"geodex_{method}_err"] = round(err(runs[0][0], ref), 5)

        def fmm():
            V, F = pp3d.read_mesh(mesh)
            return pp3d.MeshFastMarchingDistanceSolver(V, F).compute_distance([[(0, [])]])

        def heat():
            V, F = pp3d.read_mesh(mesh)
            return pp3d.MeshHeatMethodDistanceSolver(V, F, use_robust=True).compute_distance(0)

        for name, f in [("fast_marching", fmm), ("heat", heat)]:
            try:
                d, s = best_of(a.repeat, f)
                row[f"potpourri3d_{name}_s"] = round(s, 4)
                row[f"potpourri3d_{name}_err"] = round(err(np.asarray(d), ref), 5)
            except Exception as e:  # the peer's own failure is a result too
                row[f"potpourri3d_{name}_failed"] = str(e)[:120]
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
