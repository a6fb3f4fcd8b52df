"""Surface remeshing side by side: geodex, pyacvd and pymeshlab, same run.

    python3 -m venv /tmp/venv-remesh
    /tmp/venv-remesh/bin/pip install pyacvd pymeshlab numpy
    CARGO_TARGET_DIR=/work/main/target nice -n 19 cargo bench --bench remesh --no-run
    sh tests/bench/mesh_fetch_scanned.sh /tmp/scanned        # optional: the dragon
    /tmp/venv-remesh/bin/python tests/bench/compare_remesh.py [--inputs ico7,ico8,dragon] [--targets 1000,5000,20000]

Inputs: geodex's icospheres of levels 7 and 8 (163,842 and 655,362
vertices, written by `cargo bench --bench remesh -- dump`) and the Stanford
dragon from `mesh_fetch_scanned.sh` when it is there.

For each input and target vertex count:
- geodex: `cargo bench --bench remesh -- run IN K uniform OUT` (the
  `remesh` of `geodex remesh --count K` at its defaults: uniform, 5 Lloyd
  iterations); time = the remeshing alone, without reading, writing or the
  Hausdorff report.
- pyacvd: `Clustering(mesh).cluster(K)` then `create_mesh()`; time = those
  two calls.
- pymeshlab: `meshing_isotropic_explicit_remeshing` (defaults, 10
  iterations) with the target edge length searched so that the vertex count
  lands within 5 % of K (at most 3 tries, starting from the equilateral
  estimate `h = sqrt(2 A / (sqrt(3) K))`, then `h *= sqrt(V / K)`); time =
  the last (accepted) run, the total of the search beside it.

Every output is measured by one routine, `cargo bench --bench remesh --
measure IN OUT`: Hausdorff distance (geodex's `hausdorff_distance`: vertices,
edge midpoints and face centroids of each mesh against the other) over the
input's bounding-box diagonal, and the share of triangles whose smallest
angle is >= 30 degrees. Prints a markdown table and writes JSON lines to
/tmp/compare_remesh.jsonl.
"""

import argparse
import glob
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

TARGET = os.environ.get("CARGO_TARGET_DIR", "/work/main/target")
WORK = "/tmp/compare_remesh"


def bench_binary():
    found = [
        p
        for p in glob.glob(os.path.join(TARGET, "release", "deps", "remesh-*"))
        if os.access(p, os.X_OK) and not p.endswith(".d")
    ]
    if not found:
        sys.exit("build the bench first: cargo bench --bench remesh --no-run")
    return max(found, key=os.path.getmtime)


BENCH = os.environ.get("GEODEX_REMESH_BENCH") or bench_binary()


def measure(inp, out):
    r = subprocess.run([BENCH, "measure", inp, out], capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def run_geodex(inp, k, out):
    r = subprocess.run([BENCH, "run", inp, str(k), "uniform", out], capture_output=True, text=True, check=True)
    s = json.loads(r.stdout.strip().splitlines()[-1])
    return s["seconds"], {"topology_kept": s["topology_kept"], "added": s["added"]}


def run_pyacvd(inp, k, out):
    import pyacvd
    import pyvista as pv

    mesh = pv.read(inp)
    t = time.perf_counter()
    clus = pyacvd.Clustering(mesh)
    clus.cluster(k)
    new = clus.create_mesh()
    seconds = time.perf_counter() - t
    new = new.triangulate()
    faces = new.faces.reshape(-1, 4)[:, 1:]
    write_ply(out, np.asarray(new.points, dtype=np.float64), faces)
    return seconds, {}


def run_pymeshlab(inp, k, out):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(inp)
    area = ms.get_geometric_measures()["surface_area"]
    h = math.sqrt(2.0 * area / (math.sqrt(3.0) * k))
    total = 0.0
    tries = 0
    best = None
    for tries in range(1, 4):
        ms.set_current_mesh(0)
        t = time.perf_counter()
        ms.meshing_isotropic_explicit_remeshing(targetlen=pymeshlab.PureValue(h))
        seconds = time.perf_counter() - t
        total += seconds
        m = ms.current_mesh()
        v = m.vertex_number()
        if best is None or abs(v - k) < abs(best[1] - k):
            best = (seconds, v, h, m.vertex_matrix().copy(), m.face_matrix().copy())
        # Start the next try from the input again.
        ms.clear()
        ms.load_new_mesh(inp)
        if abs(v - k) <= 0.05 * k:
            break
        h *= math.sqrt(v / k)
    seconds, v, h, verts, faces = best
    write_ply(out, verts, faces)
    return seconds, {"edge_length": h, "tries": tries, "search_seconds": total}


def write_ply(path, verts, faces):
    verts = np.ascontiguousarray(verts, dtype="<f8")
    faces = np.ascontiguousarray(faces, dtype="<i4")
    with open(path, "wb") as f:
        f.write(
            (
                "ply\nformat binary_little_endian 1.0\n"
                f"element vertex {len(verts)}\nproperty double x\nproperty double y\nproperty double z\n"
                f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
            ).encode()
        )
        rows = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
        rows["n"] = 3
        rows["v"] = faces
        f.write(verts.tobytes())
        f.write(rows.tobytes())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--inputs", default="ico7,ico8,dragon")
    ap.add_argument("--targets", default="1000,5000,20000")
    ap.add_argument("--tools", default="geodex,pyacvd,pymeshlab")
    args = ap.parse_args()
    os.makedirs(WORK, exist_ok=True)
    inputs = {}
    for name in args.inputs.split(","):
        if name.startswith("ico"):
            path = os.path.join(WORK, name + ".ply")
            if not os.path.exists(path):
                subprocess.run([BENCH, "dump", name[3:], path], check=True, capture_output=True)
            inputs[name] = path
        elif name == "dragon":
            if os.path.exists("/tmp/scanned/dragon.ply"):
                inputs[name] = "/tmp/scanned/dragon.ply"
            else:
                print("dragon: not fetched (tests/bench/mesh_fetch_scanned.sh), skipped", file=sys.stderr)
        else:
            inputs[os.path.basename(name)] = name
    runners = {"geodex": run_geodex, "pyacvd": run_pyacvd, "pymeshlab": run_pymeshlab}
    rows = []
    log = open("/tmp/compare_remesh.jsonl", "a")
    for name, path in inputs.items():
        for k in map(int, args.targets.split(",")):
            for tool in args.tools.split(","):
                out = os.path.join(WORK, f"{name}_{k}_{tool}.ply")
                try:
                    seconds, extra = runners[tool](path, k, out)
                    q = measure(path, out)
                except Exception as e:  # a failed tool is reported, not fatal
                    print(f"{name} {k} {tool}: failed: {e}", file=sys.stderr)
                    continue
                row = {"input": name, "target": k, "tool": tool, "seconds": seconds, **q, **extra}
                print(json.dumps(row), file=log, flush=True)
                print(json.dumps(row), file=sys.stderr, flush=True)
                rows.append(row)
    print("| input | target | tool | vertices | min angle >= 30° | mean min angle | Hausdorff / diag | genus | non-manifold edges | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['input']} | {r['target']} | {r['tool']} | {r['vertices']} | "
            f"{100 * r['share_min_angle_ge_30']:.1f} % | {r['mean_min_angle']:.1f}° | "
            f"{r['hausdorff_relative']:.5f} | {r['genus']} | {r['non_manifold_edges']} | {r['seconds']:.2f} |"
        )


if __name__ == "__main__":
    main()
