"""The heat method on real and badly shaped meshes, end to end, side by side:
geodex (robust and cotangent Laplacians, through the CLI: start, read,
setup, solve, write) against potpourri3d's heat method (read, setup, solve,
in memory, with and without its robust Laplacian), errors against the exact
polyhedral distance from vertex 0 (geodex's exact method, checked against
pygeodesic where that finishes in reasonable time).

    python3 -m venv /tmp/venv-mesh
    /tmp/venv-mesh/bin/pip install numpy potpourri3d pygeodesic
    sh tests/bench/mesh_fetch_scanned.sh /tmp/scanned
    /tmp/venv-mesh/bin/python tests/bench/compare_robust_heat.py --slivers 6 /tmp/slivers6.obj
    OMP_NUM_THREADS=1 /tmp/venv-mesh/bin/python tests/bench/compare_robust_heat.py \
        --bin target/release/geodex /tmp/slivers6.obj /tmp/scanned/bunny.obj /tmp/scanned/dragon.ply

`--slivers L PATH` writes an icosphere of level L whose vertices are moved
most of the way towards a neighbour or an opposite edge midpoint (needles
and slivers), then as many random edge flips as faces (long obtuse
triangles), as in `tests/mesh_geodesics.rs`, and exits. Each other
argument is a mesh; one JSON line is printed per mesh and method.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np


def icosphere(level):
    t = (1 + 5 ** 0.5) / 2
    V = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    F = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(level):
        cache, nf = {}, []

        def mid(a, b):
            k = (min(a, b), max(a, b))
            if k not in cache:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))
                cache[k] = len(V) - 1
            return cache[k]

        for a, b, c in F:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        F = nf
    return np.array(V), np.array(F)


def slivers(level, path):
    V, F = icosphere(level)
    rng = np.random.default_rng(7)
    faces_of = [[] for _ in V]
    for i, f in enumerate(F):
        for v in f:
            faces_of[v].append(i)
    locked = np.zeros(len(V), bool)
    P = V.copy()
    for v in range(1, len(V)):
        if locked[v] or rng.random() < 0.3:
            continue
        f = F[faces_of[v][rng.integers(len(faces_of[v]))]]
        k = list(f).index(v)
        w1, w2 = f[(k + 1) % 3], f[(k + 2) % 3]
        target = V[w1] if rng.random() < 0.5 else (V[w1] + V[w2]) / 2
        t = 0.95 + 0.04 * rng.random()
        q = V[v] + t * (target - V[v])
        P[v] = q / np.linalg.norm(q)
        locked[v] = True
        for g in faces_of[v]:
            locked[F[g]] = True
    # As many random flips as faces (skipping folds and duplicate edges).
    F = [list(f) for f in F]
    key = lambda a, b: (min(a, b), max(a, b))
    edge_faces = {}
    for fi, f in enumerate(F):
        for k in range(3):
            edge_faces.setdefault(key(f[k], f[(k + 1) % 3]), []).append(fi)
    normal = lambda f: np.cross(P[f[1]] - P[f[0]], P[f[2]] - P[f[0]])
    flips = 0
    for _ in range(4 * len(F)):
        if flips >= len(F):
            break
        fa = int(rng.integers(len(F)))
        k = int(rng.integers(3))
        a, b, c = F[fa][k], F[fa][(k + 1) % 3], F[fa][(k + 2) % 3]
        pair = edge_faces[key(a, b)]
        fb = pair[1] if pair[0] == fa else pair[0]
        kb = F[fb].index(b)
        d = F[fb][(kb + 2) % 3]
        if c == d or key(c, d) in edge_faces:
            continue
        na, nb = [c, a, d], [d, b, c]
        n0 = normal(F[fa])
        if np.dot(normal(na), n0) <= 0 or np.dot(normal(nb), n0) <= 0:
            continue
        F[fa], F[fb] = na, nb
        del edge_faces[key(a, b)]
        edge_faces[key(c, d)] = [fa, fb]
        for e, src, dst in [(key(b, c), fa, fb), (key(a, d), fb, fa)]:
            edge_faces[e] = [dst if x == src else x for x in edge_faces[e]]
        flips += 1
    with open(path, "w") as out:
        out.write("".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P))
        out.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))


def geodex(binary, mesh, method, extra=()):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "d.npy")
        t = time.perf_counter()
        r = subprocess.run([binary, "mesh-distance", "--mesh", mesh, "--method", method, "--source-vertex", "0",
                            "--out", out, *extra], capture_output=True, text=True)
        wall = time.perf_counter() - t
        if r.returncode != 0:
            raise RuntimeError(r.stderr)
        phases = {}
        m = re.search(r"read ([\d.]+) s .*setup ([\d.]+) s .*solve ([\d.]+) s, write ([\d.]+) s", r.stderr)
        if m:
            phases = dict(zip(["read", "setup", "solve", "write"], map(float, m.groups())))
        m = re.search(r"guard ([\d.]+) s, Laplacian ([\d.]+) s, factorisations ([\d.]+) s", r.stderr)
        if m:
            phases.update(zip(["guard", "laplacian", "factorisations"], map(float, m.groups())))
        return np.load(out), wall, phases


def potpourri(mesh, robust):
    import potpourri3d as pp3d
    t = time.perf_counter()
    V, F = pp3d.read_mesh(mesh)
    s = pp3d.MeshHeatMethodDistanceSolver(V, F, use_robust=robust)
    d = s.compute_distance(0)
    return d, time.perf_counter() - t, len(V)


def pygeodesic_reference(mesh, limit_vertices):
    import potpourri3d as pp3d
    import pygeodesic.geodesic as geodesic
    V, F = pp3d.read_mesh(mesh)
    if len(V) > limit_vertices:
        return None, None
    t = time.perf_counter()
    alg = geodesic.PyGeodesicAlgorithmExact(V, F)
    d, _ = alg.geodesicDistances(np.array([0]), None)
    return d, time.perf_counter() - t


def err(d, ref):
    m = np.isfinite(ref) & (ref > 0.05 * np.nanmax(ref[np.isfinite(ref)]))
    return float(np.mean(np.abs(d[m] - ref[m]) / ref[m]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/geodex")
    ap.add_argument("--slivers", type=int)
    ap.add_argument("--pygeodesic-max", type=int, default=60000)
    ap.add_argument("meshes", nargs="+")
    a = ap.parse_args()
    if a.slivers is not None:
        slivers(a.slivers, a.meshes[0])
        return
    for mesh in a.meshes:
        ref, ref_wall, _ = geodex(a.bin, mesh, "exact")
        pyg, pyg_s = pygeodesic_reference(mesh, a.pygeodesic_max)
        row = {"mesh": os.path.basename(mesh), "vertices": len(ref), "exact_geodex_s": round(ref_wall, 3)}
        if pyg is not None and len(pyg) == len(ref):
            row["pygeodesic_s"] = round(pyg_s, 3)
            row["exact_vs_pygeodesic_max_rel"] = float(np.max(np.abs(ref - pyg)[ref > 0] / ref[ref > 0]))
        print(json.dumps(row), flush=True)
        for lap in ["robust", "cotangent"]:
            d, wall, ph = geodex(a.bin, mesh, "heat", ["--laplacian", lap])
            print(json.dumps({"mesh": os.path.basename(mesh), "tool": "geodex", "laplacian": lap,
                              "end_to_end_s": round(wall, 4), "phases_s": ph,
                              "mean_rel_err": round(err(d, ref), 5)}), flush=True)
        for robust in [True, False]:
            row = {"mesh": os.path.basename(mesh), "tool": "potpourri3d", "laplacian": "robust" if robust else "cotangent"}
            try:
                d, wall, n = potpourri(mesh, robust)
            except Exception as e:  # the peer's own failure is a result too
                row["failed"] = str(e)[:200]
                print(json.dumps(row), flush=True)
                continue
            row["read_setup_solve_s"] = round(wall, 4)
            row["mean_rel_err"] = round(err(d, ref), 5) if n == len(ref) else f"vertex count {n} != {len(ref)}"
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
