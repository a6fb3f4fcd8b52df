#!/usr/bin/env python3
"""Exact geodesic distance on icospheres: pygeodesic and gdist (tvb-gdist),
the peers of `cargo bench --bench mesh_exact`, on the same meshes.

This script installs nothing. Set up its environment once with:

    python3 -m venv /tmp/geodex-mesh-bench
    /tmp/geodex-mesh-bench/bin/pip install numpy pygeodesic tvb-gdist

and run it with that interpreter (both libraries are single-threaded):

    /tmp/geodex-mesh-bench/bin/python tests/bench/compare_mesh_exact.py --levels 6,7 --repeat 1

The icosphere is built here by the same subdivision as
`tests/mesh_support/mod.rs` (same vertex order, so vertex 0 is the same
source). Each (tool, level) runs in a child process so that its peak RSS
(ru_maxrss) is its own. One JSON line per case: seconds (best of --repeat),
peak RSS, mean / max relative error against great circles.
"""

import argparse
import json
import math
import resource
import subprocess
import sys
import time


def icosphere(level):
    import numpy as np

    t = (1.0 + 5 ** 0.5) / 2.0
    p = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]

    def unit(v):
        n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        return [v[0] / n, v[1] / n, v[2] / n]

    p = [unit(v) for v in p]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    for _ in range(level):
        mid = {}
        nf = []
        for tri in f:
            m = [0, 0, 0]
            for k in range(3):
                a, b = tri[k], tri[(k + 1) % 3]
                key = (min(a, b), max(a, b))
                if key not in mid:
                    pa, pb = p[a], p[b]
                    p.append(unit([pa[0] + pb[0], pa[1] + pb[1], pa[2] + pb[2]]))
                    mid[key] = len(p) - 1
                m[k] = mid[key]
            nf += [[tri[0], m[0], m[2]], [tri[1], m[1], m[0]], [tri[2], m[2], m[1]], [m[0], m[1], m[2]]]
        f = nf
    return np.array(p, dtype=np.float64), np.array(f, dtype=np.int32)


def one(tool, level, repeat):
    import numpy as np

    v, f = icosphere(level)
    if tool == "pygeodesic":
        import pygeodesic.geodesic as geodesic
    else:
        import gdist
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        if tool == "pygeodesic":
            algo = geodesic.PyGeodesicAlgorithmExact(v, f)
            d, _ = algo.geodesicDistances(np.array([0]), None)
        else:
            d = gdist.compute_gdist(v, f, source_indices=np.array([0], dtype=np.int32))
        best = min(best, time.perf_counter() - t0)
    g = np.arccos(np.clip(v[1:] @ v[0], -1, 1))
    e = np.abs(np.asarray(d)[1:] - g) / g
    print(json.dumps({
        "tool": tool, "level": level, "vertices": len(v), "faces": len(f), "repeat": repeat,
        "seconds": best,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "mean_rel_error": float(e.mean()), "max_rel_error": float(e.max()),
    }), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", default="6,7")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--tools", default="pygeodesic,gdist")
    ap.add_argument("--single", nargs=2, metavar=("TOOL", "LEVEL"))
    a = ap.parse_args()
    if a.single:
        one(a.single[0], int(a.single[1]), a.repeat)
        return
    for level in [int(x) for x in a.levels.split(",")]:
        for tool in a.tools.split(","):
            subprocess.run([sys.executable, __file__, "--single", tool, str(level), "--repeat", str(a.repeat)], check=False)


if __name__ == "__main__":
    main()
